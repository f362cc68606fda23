#!/usr/bin/env node
// The drive page driven by a webcam, checked against the pipeline: the
// workspace's own frames become a fake camera (a Y4M file Chromium plays in
// a loop), the page (WS/export/drive/index.html, export --formats drive)
// finds the face mesh and solves the weights and head pose in each frame it
// sees, and each of its solves is matched to the frame it saw (by the
// frame's 8 x 8 thumbnail) and compared with `headforge track`'s result for
// that frame; the page's last drawing is compared with `headforge render`
// of its frame through the Gaussian blendshapes.
//   node scripts/web/drive_webcam_check.cjs --workspace WS --out DIR [--seconds 30] [--hold 3] [--blank 0]
//        [--max-weight-error 0.1] [--max-rotation-deg 3] [--min-psnr 28]
//        [--driver WS2] [--truth ground_truth.json] [--headforge build/pipelines/headforge]
//        [--chromium /usr/bin/chromium] [--video [--fps 12.5]]
// --video: the frames go to the page as a recorded video (a WebM file given
// to its file input) instead of a fake webcam: every frame is solved in
// turn (sampled --fps a second), paced by the video's time, so the results
// do not depend on how fast the machine is; --seconds does not apply, and
// after --blank the first frame comes back for a second.
// --driver: another tracked workspace's frames drive WS's page (another
// person: the page's calibration makes the face its own); its weights and
// its head's turn since the first frame are compared with that workspace's
// track, and the drawing (another face's pose) is not.
// --truth (a simulated capture's): the page's and track's weights are both
// compared with the simulator's too, and the bounds apply to the page's
// error against the truth.
// Writes DIR/check.json (each compared solve's weights and pose among its
// rows: scripts/web/drive_error_split.cjs splits the drawing's difference
// from render's between them) and prints a table; exits 1 when a bound is
// missed.
const fs = require('fs');
const path = require('path');
const { execFileSync } = require('child_process');
const { comparePixels } = require('./compare_pixels.cjs');

const args = {};
for (let i = 2; i < process.argv.length; i += 2) {
  if (process.argv[i] === '--video') { args.video = true; --i; continue; }
  args[process.argv[i].replace(/^--/, '')] = process.argv[i + 1];
}
if (!args.workspace || !args.out) {
  console.error('usage: drive_webcam_check.cjs --workspace WS --out DIR [--seconds 30]');
  process.exit(2);
}
const root = path.join(__dirname, '..', '..');
const ws = args.workspace, out = args.out, driver = args.driver || ws, self = driver === ws;
const headforge = args.headforge || path.join(root, 'build', 'pipelines', 'headforge');
const bounds = { weight: Number(args['max-weight-error'] || 0.1), rotation: Number(args['max-rotation-deg'] || 3),
                 psnr: Number(args['min-psnr'] || 28) };
fs.mkdirSync(out, { recursive: true });

// The fake camera's file and each of its frames' thumbnails, from the Y4M
// itself (the pixels Chromium shows the page).
const frameDir = path.join(driver, 'frames', 'cam0');
const frameFiles = fs.readdirSync(frameDir).filter((f) => f.endsWith('.png')).sort();
// The driver first holds still as the avatar's rest (the capture's first
// frame, for --hold seconds: the page calibrates on it), then plays the clip.
const y4m = path.join(out, 'camera.y4m');
const sequence = path.join(out, 'sequence');
fs.rmSync(sequence, { recursive: true, force: true });
fs.mkdirSync(sequence);
const held = Math.round(25 * Number(args.hold || 3));
// --blank S: S seconds of black after the clip (the face lost: the page
// holds the avatar, then eases it back to its rest).
const blankFrames = Math.round(25 * Number(args.blank || 0));
const black = path.join(out, 'black.png');
if (blankFrames > 0) {
  const size = execFileSync('ffprobe', ['-v', 'error', '-show_entries', 'stream=width,height', '-of', 'csv=p=0',
                                        path.join(frameDir, frameFiles[0])]).toString().trim().replace(',', 'x');
  execFileSync('ffmpeg', ['-loglevel', 'error', '-y', '-f', 'lavfi', '-i', `color=black:s=${size}`, '-frames:v', '1', black]);
}
// A video's face comes back after the blank: its first frame, for a second.
const returnFrames = args.video && blankFrames > 0 ? 25 : 0;
[...Array(held).fill(path.resolve(frameDir, frameFiles[0])), ...frameFiles.map((f) => path.resolve(frameDir, f)),
 ...Array(blankFrames).fill(black), ...Array(returnFrames).fill(path.resolve(frameDir, frameFiles[0]))].forEach((f, i) =>
  fs.symlinkSync(f, path.join(sequence, String(i).padStart(6, '0') + '.png')));
execFileSync('ffmpeg', ['-loglevel', 'error', '-y', '-framerate', '25', '-i', path.join(sequence, '%06d.png'),
                        '-pix_fmt', 'yuv420p', y4m]);
// The same frames as a WebM (VP9, near lossless, a key frame every 5 frames
// for the page's frame-by-frame seeks; libvpx's realtime speed: 1 s where
// its "good" took 5).
const webm = path.join(out, 'face.webm');
if (args.video)
  execFileSync('ffmpeg', ['-loglevel', 'error', '-y', '-i', y4m, '-c:v', 'libvpx-vp9', '-crf', '4', '-b:v', '0',
                          '-g', '5', '-deadline', 'realtime', '-cpu-used', '8', '-row-mt', '1', webm]);
const probe = execFileSync('ffprobe', ['-v', 'error', '-select_streams', 'v:0', '-show_entries', 'stream=width,height',
                                       '-of', 'csv=p=0', y4m]).toString().trim().split(',').map(Number);
const [width, height] = probe;
const rgb = execFileSync('ffmpeg', ['-loglevel', 'error', '-i', y4m, '-f', 'rawvideo', '-pix_fmt', 'rgba', '-'],
                         { maxBuffer: 2 ** 31 - 1 });
const thumbnail = (data) => {
  // As the page computes it (drive_page.js).
  const t = [];
  for (let by = 0; by < 8; ++by)
    for (let bx = 0; bx < 8; ++bx) {
      let sum = 0, count = 0;
      for (let y = Math.floor(by * height / 8); y < Math.floor((by + 1) * height / 8); y += 2)
        for (let x = Math.floor(bx * width / 8); x < Math.floor((bx + 1) * width / 8); x += 2) {
          const p = 4 * (y * width + x);
          sum += data[p] + data[p + 1] + data[p + 2];
          count += 3;
        }
      t.push(sum / Math.max(1, count));
    }
  return t;
};
const frameBytes = 4 * width * height;
const thumbs = frameFiles.map((_, i) => thumbnail(rgb.subarray((held + i) * frameBytes, (held + i + 1) * frameBytes)));
const frameNumbers = frameFiles.map((f) => Number(path.basename(f, '.png')));

// The page, driven for --seconds.
const page = path.join(ws, 'export', 'drive', 'index.html');
const fps = Number(args.fps || 12.5);
execFileSync(process.execPath, [path.join(__dirname, 'drive_page.cjs'), '--page', page, '--out', out,
                                ...(args.video ? ['--video', webm, '--fps', String(fps)]
                                               : ['--webcam', y4m, '--seconds', String(args.seconds || 30)]),
                                '--chromium', args.chromium || '/usr/bin/chromium'], { stdio: 'inherit' });
const state = JSON.parse(fs.readFileSync(path.join(out, 'state.json')));
const tracking = JSON.parse(fs.readFileSync(path.join(driver, 'tracking.json')));
const basis = JSON.parse(fs.readFileSync(path.join(ws, 'export', 'drive', 'face_basis.json')));
const tracked = new Map(tracking.frames.map((f) => [f.frame, f]));
const truth = args.truth ? JSON.parse(fs.readFileSync(args.truth)).frames : null;
// The truth's camera-from-head rotation of a frame (row-major 3 x 4), and
// the turn from frame 0 to frame k in the camera's frame, R_k R_0^T, which
// is the same whatever head frame a pose is given in.
const truthPose = (k) => {
  const c = truth[k].views.cam0.cam_from_world, w = truth[k].world_from_head, out = [];
  for (let i = 0; i < 3; ++i)
    for (let j = 0; j < 4; ++j) out.push(c[i][0] * w[0][j] + c[i][1] * w[1][j] + c[i][2] * w[2][j] + (j === 3 ? c[i][3] : 0));
  return out;
};
const turn = (a, b) => {
  const out = [];
  for (let i = 0; i < 3; ++i) {
    for (let j = 0; j < 3; ++j) out.push(a[4 * i] * b[4 * j] + a[4 * i + 1] * b[4 * j + 1] + a[4 * i + 2] * b[4 * j + 2]);
    out.push(0);
  }
  return out;
};
// The driver's camera-from-head poses (row-major 3 x 4): its view's
// cam_from_world times the frame's tracked head motion, as training takes them.
const cameras = JSON.parse(fs.readFileSync(path.join(driver, 'cameras_head.json')));
const poses = new Map(tracking.frames.map((f) => {
  const v = cameras.views.find((view) => view.frame === f.frame && view.camera === cameras.cameras[0].name);
  const c = v.cam_from_world, h = f.head_motion, pose = [];
  for (let i = 0; i < 3; ++i)
    for (let j = 0; j < 4; ++j) pose.push(c[i][0] * h[0][j] + c[i][1] * h[1][j] + c[i][2] * h[2][j] + (j === 3 ? c[i][3] : 0));
  return [f.frame, pose];
}));

// A video's solve: its frame is known (the driver's clip frame at that
// position of the sequence, the first frame again after the blank).
const videoMatch = (solve) => {
  const position = Math.round(solve.video_frame * 25 / fps);
  const i = position < held ? 0 : position < held + frameFiles.length ? position - held : 0;
  return { frame: frameNumbers[i], distance: 0, second: Infinity, position };
};
const match = (thumb) => {
  let best = -1, bestD = Infinity, second = Infinity;
  thumbs.forEach((t, i) => {
    const d = Math.sqrt(t.reduce((s, v, j) => s + (v - thumb[j]) ** 2, 0) / t.length);
    if (d < bestD) { second = bestD; bestD = d; best = i; } else if (d < second) second = d;
  });
  return { frame: frameNumbers[best], distance: bestD, second };
};
const angleDeg = (a, b) => {
  // The angle of a^T b, both row-major 3 x 4 poses.
  let trace = 0;
  for (let i = 0; i < 3; ++i) for (let r = 0; r < 3; ++r) trace += a[4 * r + i] * b[4 * r + i];
  return Math.acos(Math.max(-1, Math.min(1, (trace - 1) / 2))) * 180 / Math.PI;
};
const shiftMm = (a, b) => 1000 * Math.hypot(a[3] - b[3], a[7] - b[7], a[11] - b[11]);
const watched = ['jawOpen', 'eyeBlink_L', 'eyeBlink_R'];
// The page's poses are placed on the capture's frame 0 pose (its rest).
const firstPoseOf = (b) => b.frames.find((f) => f.frame === 0).cam_from_head;
const index = Object.fromEntries(state.names.map((n, i) => [n, i]));
// The avatar's rest (its capture's first frame) and the driver's first frame.
const rest = JSON.parse(fs.readFileSync(path.join(ws, 'tracking.json'))).frames[0].expression;
const first = tracking.frames[0].expression;
const rows = [];
for (const solve of state.solves) {
  const m = args.video ? videoMatch(solve) : match(solve.thumb);
  const f = tracked.get(m.frame);
  // The held first frame is what the calibration saw, and its thumbnail
  // cannot tell it from the clip's next frames: solves made while the fake
  // camera (looping the file in real time, 25 frames a second) was in the
  // hold, or within 3 frames of it, are not compared (a video's, in the hold).
  const position = args.video ? m.position
                              : Math.floor((solve.at - state.stream_started) / 40) % (held + frameFiles.length + blankFrames);
  if (!f || solve.calibrating || position < held + (args.video ? 0 : 3)) continue;
  const errors = Object.fromEntries(watched.map((n) => [n, Math.abs(solve.weights[index[n]] - f.expression[n])]));
  const all = state.names.reduce((s, n, i) => s + Math.abs(solve.weights[i] - f.expression[n]), 0) / state.names.length;
  // Changes since the first frame: the page's weights from the avatar's rest
  // (where its calibration puts the driver's first frame) against track's
  // from the driver's first frame; for another person, what carries over.
  const relative = Object.fromEntries(watched.map((n) => [n, Math.abs((solve.weights[index[n]] - rest[n]) -
                                                                      (f.expression[n] - first[n]))]));
  const t = truth ? truth[m.frame].expression : null;
  const truthErrors = t ? Object.fromEntries(watched.map((n) => [n, Math.abs(solve.weights[index[n]] - t[n])])) : null;
  const trackTruthErrors = t ? Object.fromEntries(watched.map((n) => [n, Math.abs(f.expression[n] - t[n])])) : null;
  // The head's turn since frame 0: the page's and track's against the truth's.
  const truthTurn = t ? turn(truthPose(m.frame), truthPose(0)) : null;
  const pageTurn = turn(solve.cam_from_head, firstPoseOf(basis));
  const pageTurnError = t ? angleDeg(pageTurn, truthTurn) : null;
  const trackTurnError = t ? angleDeg(turn(poses.get(m.frame), poses.get(0)), truthTurn) : null;
  rows.push({ frame: m.frame, match_distance: m.distance, errors, relative_errors: relative, truth_errors: truthErrors,
              track_truth_errors: trackTruthErrors, page_turn_error_deg: pageTurnError,
              track_turn_error_deg: trackTurnError, all,
              turn_vs_track_deg: angleDeg(pageTurn, turn(poses.get(m.frame), poses.get(0))),
              rotation_deg: self ? angleDeg(solve.cam_from_head, poses.get(m.frame)) : null,
              shift_mm: self ? shiftMm(solve.cam_from_head, poses.get(m.frame)) : null,
              residual_px: solve.residual_px, ms_network: solve.ms_network, ms_solve: solve.ms_solve,
              weights: Array.from(solve.weights), cam_from_head: Array.from(solve.cam_from_head) });
}
const mean = (xs) => xs.reduce((s, x) => s + x, 0) / Math.max(1, xs.length);
const median = (xs) => { const s = [...xs].sort((a, b) => a - b); return s.length ? (s[(s.length - 1) >> 1] + s[s.length >> 1]) / 2 : NaN; };
const summary = {
  solves: state.solves.length, compared: rows.length, calibration: state.solves.filter((s) => s.calibrating).length,
  mae: Object.fromEntries(watched.map((n) => [n, mean(rows.map((r) => r.errors[n]))])),
  mae_all53: mean(rows.map((r) => r.all)),
  mae_relative: Object.fromEntries(watched.map((n) => [n, mean(rows.map((r) => r.relative_errors[n]))])),
  mae_truth: truth ? Object.fromEntries(watched.map((n) => [n, mean(rows.map((r) => r.truth_errors[n]))])) : null,
  turn_error_deg_median: truth ? { page: median(rows.map((r) => r.page_turn_error_deg)),
                                    track: median(rows.map((r) => r.track_turn_error_deg)) } : null,
  mae_track_truth: truth ? Object.fromEntries(watched.map((n) => [n, mean(rows.map((r) => r.track_truth_errors[n]))])) : null,
  turn_vs_track_deg_median: median(rows.map((r) => r.turn_vs_track_deg)),
  rotation_deg_median: self ? median(rows.map((r) => r.rotation_deg)) : null,
  shift_mm_median: self ? median(rows.map((r) => r.shift_mm)) : null,
  ms_network_median: median(rows.map((r) => r.ms_network)), ms_solve_median: median(rows.map((r) => r.ms_solve)),
  match_distance_max: Math.max(...rows.map((r) => r.match_distance)),
  fps: state.fps, source: args.video ? 'video' : 'webcam', video_frames: state.video_frames, user_agent: state.user_agent, lost_episodes: state.lost_episodes,
};

// The last drawing (the page's canvas when it stopped) against headforge
// render of the frame it showed.
(async () => {
  const lastSolve = state.solves[state.solves.length - 1];
  const last = !lastSolve ? -1 : args.video ? videoMatch(lastSolve).frame : match(lastSolve.thumb).frame;
  if (last >= 0 && self) {
    const renderDir = path.join(out, 'render');
    execFileSync(headforge, ['render', '--workspace', ws, '--model', path.join(ws, 'export', 'blendshapes'), '--frames',
                             String(last), '--out', renderDir], { stdio: ['ignore', 'ignore', 'inherit'] });
    const pad = String(last).padStart(6, '0');
    const dataUrl = (file) => 'data:image/png;base64,' + fs.readFileSync(file).toString('base64');
    const puppeteer = require(path.join(root, '.tools', 'node', 'node_modules', 'puppeteer-core'));
    const browser = await puppeteer.launch({ executablePath: args.chromium || '/usr/bin/chromium', headless: true,
                                             args: ['--no-sandbox'] });
    const blank = await browser.newPage();
    const compared = await blank.evaluate(comparePixels, [path.join(out, 'canvas.png'),
                                                          path.join(renderDir, `frame_${pad}.png`),
                                                          path.join(ws, 'masks', 'cam0', `${pad}.png`)].map(dataUrl));
    await browser.close();
    summary.last_frame = last;
    summary.psnr_last = compared.psnr;
  }
  const judged = truth ? summary.mae_truth : summary.mae;
  const pass = rows.length > 0 && watched.every((n) => judged[n] <= bounds.weight) &&
               (self ? summary.rotation_deg_median <= bounds.rotation && summary.psnr_last >= bounds.psnr
                     : summary.turn_vs_track_deg_median <= bounds.rotation);
  summary.bounds = bounds;
  summary.pass = pass;
  fs.writeFileSync(path.join(out, 'check.json'), JSON.stringify({ summary, rows }, null, 1));
  console.log(`${summary.source} solves: ${summary.solves} (${summary.calibration} calibrating), ${rows.length} matched to tracked frames`);
  console.log('mean absolute error against track: ' + watched.map((n) => `${n} ${summary.mae[n].toFixed(3)}`).join(', ') +
              `, all 53 ${summary.mae_all53.toFixed(3)}`);
  console.log('the same as changes since the first frame: ' +
              watched.map((n) => `${n} ${summary.mae_relative[n].toFixed(3)}`).join(', '));
  if (truth) {
    console.log('against the simulator\'s truth: the page ' + watched.map((n) => `${n} ${summary.mae_truth[n].toFixed(3)}`).join(', ') +
                '; track ' + watched.map((n) => `${n} ${summary.mae_track_truth[n].toFixed(3)}`).join(', '));
    console.log(`the head's turn since frame 0 against the truth's: the page ${summary.turn_error_deg_median.page.toFixed(2)} ` +
                `deg, track ${summary.turn_error_deg_median.track.toFixed(2)} deg (medians)`);
  }
  console.log(`the head's turn since the first frame against track's: median ${summary.turn_vs_track_deg_median.toFixed(2)} ` +
              `deg; network ${summary.ms_network_median.toFixed(1)} ms, solve ${summary.ms_solve_median.toFixed(1)} ms a frame`);
  if (self) {
    console.log(`head pose against track: median ${summary.rotation_deg_median.toFixed(2)} deg, ` +
                `${summary.shift_mm_median.toFixed(1)} mm`);
    console.log(`the page's drawing of frame ${last} against headforge render: ${summary.psnr_last.toFixed(2)} dB over the head`);
  }
  process.exit(pass ? 0 : 1);
})();
