#!/usr/bin/env node
// Where the drive page's drawing differs from `headforge render`: for every
// frame the page was matched to in a drive_webcam_check.cjs run (its last
// solve of each), the avatar drawn by `headforge render` through the
// Gaussian blendshapes with the page's weights and track's pose, with
// track's weights and the page's pose, and with both the page's, each
// against the render with track's weights and pose (the drawing the check
// compares with), over the head's mask (eroded by one pixel). The page's
// own drawing of a frame is render's with the page's weights and pose (the
// check's 55-60 dB between them), so this tells whether its weights or its
// pose cost the drawing, over many frames instead of the last.
//   node scripts/web/drive_error_split.cjs --workspace WS --check DIR [--out DIR/split]
//        [--headforge build/pipelines/headforge] [--chromium /usr/bin/chromium]
// WS: the workspace the check drove itself (not --driver). Prints the
// PSNRs (mean and median over the frames) and writes OUT/split.json.
const fs = require('fs');
const path = require('path');
const { execFileSync } = require('child_process');
const { comparePixels } = require('./compare_pixels.cjs');

const args = {};
for (let i = 2; i < process.argv.length; i += 2) args[process.argv[i].replace(/^--/, '')] = process.argv[i + 1];
if (!args.workspace || !args.check) {
  console.error('usage: drive_error_split.cjs --workspace WS --check DIR [--out DIR/split]');
  process.exit(2);
}
const root = path.join(__dirname, '..', '..');
const ws = path.resolve(args.workspace), out = path.resolve(args.out || path.join(args.check, 'split'));
const headforge = args.headforge || path.join(root, 'build', 'pipelines', 'headforge');
const readJson = (f) => JSON.parse(fs.readFileSync(f, 'utf8'));
const pad = (n) => String(n).padStart(6, '0');

const check = readJson(path.join(args.check, 'check.json'));
const rows = check.rows.filter((r) => r.weights && r.cam_from_head && r.rotation_deg !== null);
if (!rows.length) {
  console.error('drive_error_split: check.json has no compared solve with its weights and pose ' +
                '(run drive_webcam_check.cjs again, on the workspace itself)');
  process.exit(2);
}
const last = new Map();  // frame -> its last solve
for (const r of rows) last.set(r.frame, r);
const frames = [...last.keys()].sort((a, b) => a - b);
const tracking = readJson(path.join(ws, 'tracking.json'));
const names = readJson(path.join(ws, 'export', 'drive', 'face_basis.json')).expression_names;
const cameras = readJson(path.join(ws, 'cameras_head.json'));
const lens = cameras.cameras[0].name;
const median = (xs) => { const s = [...xs].sort((a, b) => a - b); return (s[(s.length - 1) >> 1] + s[s.length >> 1]) / 2; };
const viewOf = (frame) => cameras.views.find((v) => v.camera === lens && v.frame === frame).cam_from_world;
// Track's camera-from-head pose of a tracking frame record: V M, 3 x 4.
const trackPose = (f) => {
  const V = viewOf(f.frame), M = f.head_motion;
  return [0, 1, 2].map((i) => [0, 1, 2, 3].map((j) => [0, 1, 2, 3].reduce((s, k) => s + V[i][k] * M[k][j], 0)));
};

// head_motion for the page's camera-from-head pose P (row-major 3 x 4) seen
// through view V (4 x 4): V^-1 P.
function headMotion(V, P) {
  const M = [];
  for (let i = 0; i < 3; ++i) {
    const row = [0, 1, 2, 3].map((j) => [0, 1, 2].reduce((s, k) => s + V[k][i] * P[4 * k + j], 0));
    row[3] -= [0, 1, 2].reduce((s, k) => s + V[k][i] * V[k][3], 0);
    M.push(row);
  }
  M.push([0, 0, 0, 1]);
  return M;
}

// A workspace that is WS with tracking.json changed by `edit` on each
// compared frame, rendered at those frames.
function renderVariant(name, edit) {
  const dir = path.join(out, name), variant = path.join(dir, 'workspace');
  fs.rmSync(dir, { recursive: true, force: true });
  fs.mkdirSync(variant, { recursive: true });
  for (const entry of fs.readdirSync(ws))
    if (entry !== 'tracking.json') fs.symlinkSync(path.join(ws, entry), path.join(variant, entry));
  const changed = JSON.parse(JSON.stringify(tracking));
  if (edit)
    for (const f of changed.frames)
      if (last.has(f.frame)) edit(f, last.get(f.frame));
  fs.writeFileSync(path.join(variant, 'tracking.json'), JSON.stringify(changed));
  execFileSync(headforge, ['render', '--workspace', variant, '--model', path.join(ws, 'export', 'blendshapes'),
                           '--frames', frames.join(','), '--out', path.join(dir, 'render')],
               { stdio: ['ignore', 'ignore', 'pipe'] });
  return (frame) => path.join(dir, 'render', `frame_${pad(frame)}.png`);
}

const pageWeights = (f, r) => names.forEach((n, k) => { f.expression[n] = r.weights[k]; });
// part: 'turn' keeps track's place of the head (its origin in the camera),
// 'place' keeps track's turn; otherwise the page's whole pose.
const pagePose = (f, r, part) => {
  const P = Array.from(r.cam_from_head);
  if (part) {
    const T = trackPose(f);
    for (let i = 0; i < 3; ++i)
      for (let j = 0; j < 4; ++j)
        if ((part === 'turn') === (j === 3)) P[4 * i + j] = T[i][j];
  }
  f.head_motion = headMotion(viewOf(f.frame), P);
};
(async () => {
  fs.mkdirSync(out, { recursive: true });
  const track = renderVariant('track', null);
  const variants = {
    "the page's weights, track's pose": renderVariant('page_weights', pageWeights),
    "track's weights, the page's pose": renderVariant('page_pose', pagePose),
    "the page's weights and pose": renderVariant('page_both', (f, r) => { pageWeights(f, r); pagePose(f, r); }),
    // The pose's two parts: the head's turn (about its own origin) and its
    // place.
    "track's weights, the page's turn": renderVariant('page_turn', (f, r) => pagePose(f, r, 'turn')),
    "track's weights, the page's place": renderVariant('page_place', (f, r) => pagePose(f, r, 'place')),
  };
  const puppeteer = require(path.join(root, '.tools', 'node', 'node_modules', 'puppeteer-core'));
  const browser = await puppeteer.launch({ executablePath: args.chromium || '/usr/bin/chromium', headless: true,
                                           args: ['--no-sandbox'] });
  const page = await browser.newPage();
  const url = (file) => 'data:image/png;base64,' + fs.readFileSync(file).toString('base64');
  const result = { workspace: ws, check: path.resolve(args.check), frames, variants: {} };
  // The page's head against track's in the camera, over every compared
  // solve (mm; x right, y down, z away).
  const shift = rows.map((r) => {
    const T = trackPose(tracking.frames.find((t) => t.frame === r.frame));
    return [0, 1, 2].map((i) => 1000 * (r.cam_from_head[4 * i + 3] - T[i][3]));
  });
  result.shift_mm = ['x', 'y', 'z'].map((axis, c) => ({
    axis, mean: shift.reduce((s, d) => s + d[c], 0) / shift.length, median_abs: median(shift.map((d) => Math.abs(d[c]))),
    max_abs: Math.max(...shift.map((d) => Math.abs(d[c]))) }));
  for (const [name, image] of Object.entries(variants)) {
    const psnr = [];
    for (const frame of frames)
      psnr.push((await page.evaluate(comparePixels, [image(frame), track(frame),
                                                      path.join(ws, 'masks', lens, `${pad(frame)}.png`)].map(url))).psnr);
    result.variants[name] = { psnr, mean: psnr.reduce((s, x) => s + x, 0) / psnr.length, median: median(psnr) };
  }
  await browser.close();
  fs.writeFileSync(path.join(out, 'split.json'), JSON.stringify(result, null, 1));
  console.log(`drive_error_split: ${frames.length} frames (${frames.join(' ')}), against render with track's weights and pose, over the head:`);
  for (const [name, v] of Object.entries(result.variants))
    console.log(`  ${name.padEnd(36)} mean ${v.mean.toFixed(2)} dB, median ${v.median.toFixed(2)} dB`);
  console.log(`the page's head against track's over ${rows.length} solves (mm; mean, median and largest size): ` +
              result.shift_mm.map((a) => `${a.axis} ${a.mean.toFixed(1)}, ${a.median_abs.toFixed(1)}, ${a.max_abs.toFixed(1)}`).join('; '));
})().catch((e) => {
  console.error('drive_error_split: ' + (e.stack || e));
  process.exit(1);
});
