#!/usr/bin/env node
// Exported Gaussians (a KHR_gaussian_splatting GLB, a 3D Gaussian Splatting
// PLY, or a baked clip's frame read back to PLY) drawn by PlayCanvas in
// headless Chromium through frame K's camera of a trained workspace, against
// `headforge render` of frame K: prints the PSNR over the frame's head mask
// (resized to --size, eroded by one pixel) and exits 1 below --min-psnr. The
// check train_test runs on a simulated capture, for any workspace.
//   node scripts/web/compare_splats.cjs --workspace WS --frame K --file WS/export/gaussians.glb
//        [--size 128] [--min-psnr 30] [--model DIR (render's --model)] [--headforge build/pipelines/headforge]
//        [--chromium /usr/bin/chromium]
const fs = require('fs');
const os = require('os');
const path = require('path');
const { execFileSync } = require('child_process');

const args = {};
for (let i = 2; i < process.argv.length; i += 2) args[process.argv[i].replace(/^--/, '')] = process.argv[i + 1];
const root = path.join(__dirname, '..', '..');
if (!args.workspace || args.frame === undefined || !args.file) {
  console.error('usage: compare_splats.cjs --workspace WS --frame K --file FILE [--size 128] [--min-psnr 30]');
  process.exit(2);
}
const ws = args.workspace, frame = Number(args.frame), size = Number(args.size || 128);
const headforge = args.headforge || path.join(root, 'build', 'pipelines', 'headforge');
const chromium = args.chromium || '/usr/bin/chromium';
const puppeteer = require(path.join(root, '.tools', 'node', 'node_modules', 'puppeteer-core'));
const pad = (n) => String(n).padStart(6, '0');

// Frame K's camera in the head frame: its view times the tracked head motion (4x4, row by row).
const cameras = JSON.parse(fs.readFileSync(path.join(ws, 'cameras_head.json')));
const tracking = JSON.parse(fs.readFileSync(path.join(ws, 'tracking.json')));
const view = cameras.views.find((v) => v.frame === frame);
const tracked = tracking.frames.find((f) => f.frame === frame);
if (!view || !tracked) {
  console.error(`compare_splats: frame ${frame} has no camera or no tracking in ${ws}`);
  process.exit(2);
}
const times = (a, b) => a.map((row, i) => row.map((_, j) => row.reduce((s, x, k) => s + x * b[k][j], 0)));
const pose = times(view.cam_from_world, tracked.head_motion);
const lens = cameras.cameras[0];
const scale = size / Math.max(lens.width, lens.height);
const query = `fx=${lens.fx * scale}&fy=${lens.fy * scale}&cx=${(lens.cx + 0.5) * scale - 0.5}` +
              `&cy=${(lens.cy + 0.5) * scale - 0.5}&pose=${pose.flat().join(',')}`;

const tmp = fs.mkdtempSync(path.join(os.tmpdir(), 'hf_compare_'));
execFileSync(headforge, ['render', '--workspace', ws, '--frames', String(frame), '--background', '0', '--resolution',
                         String(size), '--out', path.join(tmp, 'render'), ...(args.model ? ['--model', args.model] : [])],
             { stdio: ['ignore', 'ignore', 'inherit'] });
const shot = path.join(tmp, 'playcanvas.png');
execFileSync(process.execPath, [path.join(__dirname, 'screenshot.cjs'), '--page', 'splat_view.html', '--file', args.file,
                                '--query', query, '--width', String(size), '--height', String(size), '--out', shot,
                                '--chromium', chromium], { stdio: 'inherit' });

const dataUrl = (file) => 'data:image/png;base64,' + fs.readFileSync(file).toString('base64');
(async () => {
  const browser = await puppeteer.launch({ executablePath: chromium, headless: true, args: ['--no-sandbox'] });
  const page = await browser.newPage();
  const result = await page.evaluate(async (urls, size) => {
    const pixels = async (url) => {
      const image = new Image();
      image.src = url;
      await image.decode();
      const canvas = new OffscreenCanvas(size, size);
      const context = canvas.getContext('2d');
      context.imageSmoothingQuality = 'high';
      context.drawImage(image, 0, 0, size, size);
      return context.getImageData(0, 0, size, size).data;
    };
    const [ours, theirs, mask] = await Promise.all(urls.map(pixels));
    const inside = (x, y) => x >= 0 && y >= 0 && x < size && y < size && mask[4 * (y * size + x)] > 128;
    let sum = 0, count = 0;
    for (let y = 0; y < size; ++y)
      for (let x = 0; x < size; ++x) {
        let kept = true;  // eroded by one pixel
        for (let dy = -1; dy <= 1 && kept; ++dy)
          for (let dx = -1; dx <= 1 && kept; ++dx) kept = inside(x + dx, y + dy);
        if (!kept) continue;
        for (let c = 0; c < 3; ++c) sum += (ours[4 * (y * size + x) + c] - theirs[4 * (y * size + x) + c]) ** 2;
        ++count;
      }
    return { psnr: 10 * Math.log10(255 * 255 / Math.max(sum / (3 * count), 1e-9)), count };
  }, [path.join(tmp, 'render', `frame_${pad(frame)}.png`), shot, path.join(ws, 'masks', 'cam0', `${pad(frame)}.png`)]
      .map(dataUrl), size);
  await browser.close();
  fs.rmSync(tmp, { recursive: true, force: true });
  console.log(`PlayCanvas (${path.basename(args.file)}) against headforge render, frame ${frame} at ${size} px: ` +
              `${result.psnr.toFixed(2)} dB over ${result.count} px of head`);
  process.exit(result.count > 0 && result.psnr >= Number(args['min-psnr'] || 30) ? 0 : 1);
})();
