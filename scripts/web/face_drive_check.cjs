#!/usr/bin/env node
// Checks export/web/face_drive.js (the drive page's face tracker and solver)
// on a workspace's frames against the C++ pipeline's results:
//  - the tracker's 468 points against landmarks.json's face mesh (vision/
//    face_mesh.cc), followed from frame to frame (the page's rule) and seeded
//    like the C++ ingest (each frame's square from its own 68 points, then
//    once more from its mesh: the crop and network alone);
//  - solveFace, frame by frame with `previous`, fed the C++ mesh points and
//    the tracker's, against tracking.json: mean absolute error of jawOpen and
//    the blinks, the head's camera-frame rotation error and its turn since
//    the first frame against track's, and times.
// The solver runs with the basis as exported and with its neutral calibrated
// on the first frames (calibrateNeutral over --calibration-frames, 10, taken
// as a neutral face): the page's way, since the face mesh places its points,
// the lips' and the chin's above all, unlike the 68 points the basis' subject
// was tracked with. Prints a table, writes --out FILE (JSON) and exits 1 when a target
// is missed on the calibrated runs (weights <= 0.1 mean absolute error,
// turn since the first frame <= 3 deg median: the page draws the head's
// motion since its calibration on the avatar's rest pose, so a constant
// offset of the camera-frame rotation does not reach the drawing).
//   node scripts/web/face_drive_check.cjs --workspace WS --basis BASIS.json [--frames N] [--out FILE]
//        [--calibration-frames 10] [--backend wasm|cpu] [--threads 1]
// BASIS.json: the drive basis `headforge export --formats drive` writes.
const fs = require('fs');
const path = require('path');
const { execFileSync } = require('child_process');

const args = {};
for (let i = 2; i < process.argv.length; i += 2) args[process.argv[i].replace(/^--/, '')] = process.argv[i + 1];
const root = path.join(__dirname, '..', '..');
if (!args.workspace || !args.basis) {
  console.error('usage: face_drive_check.cjs --workspace WS --basis BASIS.json [--frames N] [--out FILE]');
  process.exit(2);
}
const ws = args.workspace;
const modules = args.modules || path.join(root, '.tools', 'node', 'node_modules');
const models = args.models || path.join(root, '.tools', 'human-models', 'models');
const tf = require(path.join(modules, '@tensorflow', 'tfjs'));
const wasm = require(path.join(modules, '@tensorflow', 'tfjs-backend-wasm'));
const Drive = require(path.join(root, 'export', 'web', 'face_drive.js'));
const readJson = (f) => JSON.parse(fs.readFileSync(f, 'utf8'));
const pad = (n) => String(n).padStart(6, '0');
const median = (a) => {
  const s = Float64Array.from(a).sort();
  return s.length ? (s[(s.length - 1) >> 1] + s[s.length >> 1]) / 2 : NaN;
};
const mean = (a) => a.reduce((x, y) => x + y, 0) / a.length;
const now = () => Number(process.hrtime.bigint()) / 1e6;

// A frame of the workspace as RGB bytes.
function readFrame(camera, index, width, height) {
  const file = path.join(ws, 'frames', camera, pad(index) + '.png');
  const rgb = execFileSync('ffmpeg', ['-v', 'error', '-i', file, '-f', 'rawvideo', '-pix_fmt', 'rgb24', '-']);
  if (rgb.length !== width * height * 3) throw new Error(`${file}: ${rgb.length} bytes, not ${width} x ${height} RGB`);
  return { data: new Uint8ClampedArray(rgb.buffer, rgb.byteOffset, rgb.length), width, height };
}

// vision/face_mesh.cc's FaceRegionFrom68: the eyes' line, the box of the 68
// points 1.8 times its longer side, shifted up a tenth of its height.
function regionFrom68(points) {
  const eye = (a) => [0, 1].map((c) => points.slice(a, a + 6).reduce((s, p) => s + p[c], 0) / 6);
  const [right, left] = [eye(36), eye(42)];
  const xs = points.map((p) => p[0]), ys = points.map((p) => p[1]);
  const [x0, x1, y0, y1] = [Math.min(...xs), Math.max(...xs), Math.min(...ys), Math.max(...ys)];
  const angle = Math.atan2(left[1] - right[1], left[0] - right[0]), h = y1 - y0;
  return { centre: [(x0 + x1) / 2 + 0.1 * h * Math.sin(angle), (y0 + y1) / 2 - 0.1 * h * Math.cos(angle)],
           side: Math.max(x1 - x0, y1 - y0) * 1.8, angle };
}

// Median and largest image distance between two sets of 468 points.
function pointDistance(a, b) {
  const d = [];
  for (let i = 0; i < 468; i++) d.push(Math.hypot(a[3 * i] - b[3 * i], a[3 * i + 1] - b[3 * i + 1]));
  return { median: median(d), max: Math.max(...d) };
}

async function loadTracker() {
  if (args.threads && wasm.setThreadsCount) wasm.setThreadsCount(Number(args.threads));
  let backend = args.backend || 'wasm';
  try {
    await tf.setBackend(backend);
    await tf.ready();
  } catch (e) {
    backend = 'cpu';
    await tf.setBackend('cpu');
    await tf.ready();
  }
  const bin = fs.readFileSync(path.join(models, 'facemesh.bin'));
  const model = await Drive.loadFaceMesh(tf, readJson(path.join(models, 'facemesh.json')),
                                         bin.buffer.slice(bin.byteOffset, bin.byteOffset + bin.length));
  return { backend, tracker: new Drive.FaceMeshTracker(tf, model) };
}

// The tracker over the frames, followed and C++-seeded; the points of each.
async function runTracker(tracker, camera, frames, lens) {
  const rows = [];
  const seeded = new Drive.FaceMeshTracker(tracker.tf, tracker.model);
  const runMs = [];
  for (const f of frames) {
    const image = readFrame(camera, f.index, lens.width, lens.height);
    const before = tracker.stats.runMs, runs = tracker.stats.runs, searched = !tracker.last;
    const followed = await tracker.track(image);
    if (!searched && tracker.stats.runs === runs + 1) runMs.push(tracker.stats.runMs - before);
    let fromC = null;
    if (f.points) {
      const [a] = await seeded.predict(image, [regionFrom68(f.points)]);
      const [b] = await seeded.predict(image, [Drive.regionFromMesh(a.points)]);
      fromC = b.score >= a.score * 0.5 ? b : a;
    }
    const row = { frame: f.index, found: followed.found, score: followed.score, searched, points: followed.points };
    if (f.mesh && followed.found) row.followed = pointDistance(followed.points, f.mesh);
    if (f.mesh && fromC) row.seeded = pointDistance(fromC.points, f.mesh);
    if (fromC) row.regions = {
      centre_px: Math.hypot(fromC.region.centre[0] - followed.region.centre[0], fromC.region.centre[1] - followed.region.centre[1]),
      side_ratio: followed.region.side / fromC.region.side,
      angle_deg: (followed.region.angle - fromC.region.angle) * 180 / Math.PI,
    };
    rows.push(row);
  }
  return { rows, runMs };
}

// The search on webcam-like 640 x 480 frames: the first frame scaled by s and
// placed at (x, y) on black; found, and the points against the C++ mesh moved
// alike (median px).
async function searchCheck(tf, model, camera, first, lens) {
  const out = [];
  for (const [s, x0, y0] of [[0.9, 80, 0], [0.7, 0, 60], [0.5, 100, 20], [0.5, 350, 0], [0.35, 380, 150], [0.3, 250, 120], [0.25, 100, 100]]) {
    const n = Math.round(lens.width * s), W = 640, H = 480;
    const file = path.join(ws, 'frames', camera, pad(first.index) + '.png');
    const rgb = execFileSync('ffmpeg', ['-v', 'error', '-i', file, '-vf', `scale=${n}:${n}`, '-f', 'rawvideo', '-pix_fmt', 'rgb24', '-']);
    const data = new Uint8ClampedArray(W * H * 4);
    for (let y = 0; y < n && y + y0 < H; y++)
      for (let x = 0; x < n && x + x0 < W; x++)
        for (let c = 0; c < 3; c++) data[((y + y0) * W + x + x0) * 4 + c] = rgb[(y * n + x) * 3 + c];
    const tracker = new Drive.FaceMeshTracker(tf, model), k = n / lens.width;
    const t0 = now();
    const r = await tracker.track({ data, width: W, height: H });
    const ms = now() - t0;
    const moved = first.mesh.map((v, i) => (i % 3 === 0 ? v * k + x0 : i % 3 === 1 ? v * k + y0 : v));
    out.push({ scale: s, x0, y0, found: r.found, score: r.score, ms, px: r.found ? pointDistance(r.points, moved).median : null });
  }
  return out;
}

// solveFace over a sequence of point sets (null: no points, the chain restarts).
// options: solveFace's (e.g. the basis' expression prior).
function runSolver(sequence, basis, lens, truth, names, options = {}) {
  const K = names.length, watched = ['jawOpen', 'eyeBlink_L', 'eyeBlink_R'];
  const err = Object.fromEntries(watched.map((n) => [n, []]));
  const all = [], rot = [], trans = [], ms = [], residual = [], iterations = [], perWeight = new Float64Array(K);
  const depth = [];  // the head's distance from the camera against track's (mm)
  const turn = [];   // the head's turn since the first frame against track's (deg)
  let firstR = null, firstTruthR = null;
  let previous = null;
  sequence.forEach((points, f) => {
    if (!points) {
      previous = null;
      return;
    }
    const t0 = now();
    const r = Drive.solveFace(points, basis, lens, previous, options);
    const t1 = now();
    if (previous) ms.push(t1 - t0);
    previous = r;
    residual.push(r.residual_px);
    iterations.push(r.iterations);
    const tr = truth[f];
    for (const n of watched) err[n].push(Math.abs(r.weights[names.indexOf(n)] - tr.weights[n]));
    let sum = 0;
    for (let k = 0; k < K; k++) {
      const e = Math.abs(r.weights[k] - (tr.weights[names[k]] || 0));
      sum += e;
      perWeight[k] += e;
    }
    all.push(sum / K);
    rot.push(Drive.rotationAngleDeg(Drive.mul3(r.rotation, Drive.transpose3(tr.R))));
    if (!firstR) [firstR, firstTruthR] = [r.rotation, tr.R];
    turn.push(Drive.rotationAngleDeg(Drive.mul3(Drive.mul3(r.rotation, Drive.transpose3(firstR)),
                                                Drive.transpose3(Drive.mul3(tr.R, Drive.transpose3(firstTruthR))))));
    trans.push(Math.hypot(...r.translation.map((x, c) => x - tr.t[c])) * 1000);
    depth.push((r.translation[2] - tr.t[2]) * 1000);
  });
  const out = { frames: rot.length, rotation_deg_median: median(rot), rotation_deg_max: Math.max(...rot),
                turn_deg_median: median(turn),
                translation_mm_median: median(trans), all_weights_mae: mean(all), residual_px_median: median(residual),
                iterations_mean: mean(iterations), ms_per_solve_median: median(ms), ms_per_solve_max: Math.max(...ms) };
  for (const n of watched) out[n + '_mae'] = mean(err[n]);
  // How far the head's distance strays from track's over the frames, from
  // the first's: the calibration sets the first.
  out.depth_from_first_mm = { min: Math.min(...depth) - depth[0], max: Math.max(...depth) - depth[0] };
  // The five weights furthest from track's (mean absolute).
  out.worst_weights = [...perWeight].map((e, k) => [names[k], e / Math.max(1, rot.length)])
    .sort((a, b) => b[1] - a[1]).slice(0, 5);
  return out;
}

// The tracked truth per frame: weights by name, cam_from_head = the view's
// cam_from_world times the head motion.
function loadTruth(camera) {
  const cams = readJson(path.join(ws, 'cameras_head.json')), tracking = readJson(path.join(ws, 'tracking.json'));
  const lens = cams.cameras.find((c) => c.name === camera);
  const truth = {};
  for (const tf of tracking.frames) {
    const view = cams.views.find((v) => v.frame === tf.frame && v.camera === camera);
    if (!view) continue;
    const V = view.cam_from_world, M = tf.head_motion;
    const P = V.map((row) => [0, 1, 2, 3].map((j) => row.reduce((s, x, k) => s + x * M[k][j], 0)));
    truth[tf.frame] = { weights: tf.expression, R: [...P[0].slice(0, 3), ...P[1].slice(0, 3), ...P[2].slice(0, 3)],
                        t: [P[0][3], P[1][3], P[2][3]] };
  }
  return { lens, truth };
}

function printTable(report) {
  const t = report.tracker, line = (k, v) => console.log('  ' + k.padEnd(44) + v);
  console.log(`face_drive_check: ${ws}, ${t.frames} frames, backend ${report.backend}`);
  line('tracker vs C++ mesh, followed (median px)', `${t.followed_px_median.toFixed(2)} (frames' max ${t.followed_px_max.toFixed(2)})`);
  line('tracker vs C++ mesh, C++-seeded (median px)', `${t.seeded_px_median.toFixed(2)} (frames' max ${t.seeded_px_max.toFixed(2)})`);
  line('regions, followed vs C++-seeded', `centre ${t.region_centre_px_median.toFixed(1)} px, side x${t.region_side_ratio_median.toFixed(3)}`);
  line('face lost / searched', `${t.lost} / ${t.searched}`);
  line('network run (ms, 1 crop, median)', t.run_ms_median.toFixed(1));
  line('search, 640x480 (ms, median)', t.search_ms_median.toFixed(0));
  line('search (scale@x,y: px or lost)', t.searches.map((r) => `${r.scale}@${r.x0},${r.y0}: ${r.found ? r.px.toFixed(1) : 'lost'}`).join('  '));
  console.log('  ' + 'solveFace fed'.padEnd(30) + ['jawOpen', 'blink_L', 'blink_R', 'all53', 'rot deg', 'turn deg', 'trans mm', 'resid px', 'iters', 'ms'].map((s) => s.padStart(9)).join(''));
  for (const [name, s] of Object.entries(report.solve)) {
    const v = [s.jawOpen_mae, s.eyeBlink_L_mae, s.eyeBlink_R_mae, s.all_weights_mae, s.rotation_deg_median, s.turn_deg_median,
               s.translation_mm_median, s.residual_px_median, s.iterations_mean, s.ms_per_solve_median];
    console.log('  ' + name.padEnd(30) + v.map((x, i) => x.toFixed(i < 4 ? 3 : 2).padStart(9)).join(''));
    console.log('  ' + ''.padEnd(30) + `distance against track's, from the first frame's: ${s.depth_from_first_mm.min.toFixed(1)} ` +
                `to ${s.depth_from_first_mm.max.toFixed(1)} mm`);
    console.log('  ' + ''.padEnd(30) + 'furthest: ' + s.worst_weights.map(([n, e]) => `${n} ${e.toFixed(3)}`).join(', '));
  }
}

(async () => {
  const camera = args.camera || 'cam0';
  const basis = readJson(args.basis);
  const landmarks = readJson(path.join(ws, 'landmarks.json')).cameras[camera];
  const { lens, truth } = loadTruth(camera);
  const count = Math.min(Number(args.frames || landmarks.length), landmarks.length);
  const frames = landmarks.slice(0, count).map((l) => ({ index: l.index, points: l.found ? l.points : null, mesh: l.mesh || null }));
  const { backend, tracker } = await loadTracker();
  const tracked = await runTracker(tracker, camera, frames, lens);

  const searches = await searchCheck(tf, tracker.model, camera, frames.find((f) => f.mesh), lens);
  const rows = tracked.rows, followed = rows.filter((r) => r.followed), seeded = rows.filter((r) => r.seeded);
  const report = { workspace: ws, basis: args.basis, backend, tracker: {
    frames: rows.length, lost: rows.filter((r) => !r.found).length, searched: rows.filter((r) => r.searched).length,
    followed_px_median: median(followed.map((r) => r.followed.median)),
    followed_px_max: Math.max(...followed.map((r) => r.followed.median)),
    seeded_px_median: median(seeded.map((r) => r.seeded.median)),
    seeded_px_max: Math.max(...seeded.map((r) => r.seeded.median)),
    region_centre_px_median: median(rows.filter((r) => r.regions).map((r) => r.regions.centre_px)),
    region_side_ratio_median: median(rows.filter((r) => r.regions).map((r) => r.regions.side_ratio)),
    run_ms_median: median(tracked.runMs),
    search_ms_median: median(searches.map((r) => r.ms)),
    searches,
  } };
  const names = basis.expression_names, calibrationFrames = Number(args['calibration-frames'] || 10);
  report.calibration_frames = calibrationFrames;
  const inTruth = frames.map((f) => truth[f.index] !== undefined);
  const seqOf = (get) => frames.map((f, i) => (inTruth[i] ? get(f, i) : null));
  const truthSeq = frames.map((f) => truth[f.index]);
  // Each source of points with the basis as exported, and with its neutral
  // calibrated on the first frame (taken as a neutral face), as the page does.
  const calibrated = (seq) => {
    const sets = seq.filter((p) => p).slice(0, calibrationFrames), fits = [];
    for (const p of sets) fits.push(Drive.solveFace(p, basis, lens, fits[fits.length - 1] || null, { poseOnly: true }));
    return Drive.calibrateNeutral(sets, basis, lens, fits);
  };
  const cpp = seqOf((f) => f.mesh), js = seqOf((f, i) => (rows[i].found ? rows[i].points : null));
  report.solve = {
    'C++ mesh': runSolver(cpp, basis, lens, truthSeq, names),
    'C++ mesh, calibrated': runSolver(cpp, calibrated(cpp), lens, truthSeq, names),
    'JS tracker': runSolver(js, basis, lens, truthSeq, names),
    'JS tracker, calibrated': runSolver(js, calibrated(js), lens, truthSeq, names),
  };
  // With the avatar's training expressions as the weights' prior (the
  // page's way, where the basis carries it).
  if (basis.expression_prior) {
    const prior = { expressionPrior: basis.expression_prior };
    report.solve['C++ mesh, calibrated, prior'] = runSolver(cpp, calibrated(cpp), lens, truthSeq, names, prior);
    report.solve['JS tracker, calibrated, prior'] = runSolver(js, calibrated(js), lens, truthSeq, names, prior);
  }
  const cold = [];
  for (const f of frames.slice(0, 10)) if (f.mesh) {
    const t0 = now();
    Drive.solveFace(f.mesh, basis, lens, null);
    cold.push(now() - t0);
  }
  report.solve_first_frame_ms_median = median(cold);
  printTable(report);
  console.log('  first-frame solve (no previous): ' + report.solve_first_frame_ms_median.toFixed(1) + ' ms median');
  const misses = [];
  for (const [name, s] of Object.entries(report.solve)) {
    if (!name.includes('calibrated')) continue;  // the targets hold for the page's way
    for (const w of ['jawOpen', 'eyeBlink_L', 'eyeBlink_R']) if (!(s[w + '_mae'] <= 0.1)) misses.push(`${name}: ${w} ${s[w + '_mae'].toFixed(3)} > 0.1`);
    // The page places the head's motion since its calibration on the
    // avatar's rest, so its turn since the first frame is what it draws.
    if (!(s.turn_deg_median <= 3)) misses.push(`${name}: turn since the first frame ${s.turn_deg_median.toFixed(2)} deg > 3`);
  }
  report.misses = misses;
  if (args.out) fs.writeFileSync(args.out, JSON.stringify(report, null, 1) + '\n');
  for (const m of misses) console.log('  MISSED ' + m);
  process.exit(misses.length ? 1 : 0);
})().catch((e) => {
  console.error('face_drive_check: ' + (e.stack || e));
  process.exit(2);
});
