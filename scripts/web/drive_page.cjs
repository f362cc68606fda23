#!/usr/bin/env node
// Opens a drive page (export --formats drive: drive/index.html) in headless
// Chromium (puppeteer-core, software WebGL) and writes what it drew and
// what it exposes to scripts:
//   node scripts/web/drive_page.cjs --page WS/export/drive/index.html --out DIR
//        [--frame K]                      hold frame K of the capture's take
//        [--take FILE [--frame K]]        play a Live Link Face CSV or tracking.json (frame K held)
//        [--webcam FILE.y4m --seconds S]  drive from a fake webcam fed from the file, for S seconds
//        [--video FILE.webm [--fps N] [--video-timeout S]]  drive from a recorded video (every frame, N a
//                                         second), to its end (at most S seconds, 7200)
//        [--weights JSON]                 pose by a script: {"jawOpen": 0.8, ...}
//        [--compare REF.png --mask MASK.png [--min-psnr 28]]
//        [--chromium /usr/bin/chromium]
// Writes DIR/canvas.png (the canvas's pixels; DIR/mesh.png, the mesh
// avatar's, where the page draws it) and DIR/state.json (the mode,
// frame, frame rate, weights, the webcam's solves, console errors; with
// --compare, the PSNR of the canvas against REF over MASK (resized to the
// canvas, eroded by one pixel): `headforge render` of the same frame and
// the workspace's head mask). Exits 1 on a console or page error, or a PSNR
// under --min-psnr.
const fs = require('fs');
const path = require('path');

const args = {};
for (let i = 2; i < process.argv.length; i += 2) args[process.argv[i].replace(/^--/, '')] = process.argv[i + 1];
const modules = path.join(__dirname, '..', '..', '.tools', 'node', 'node_modules');
const puppeteer = require(path.join(modules, 'puppeteer-core'));
const { comparePixels } = require('./compare_pixels.cjs');
const { kChromiumFlags } = require('./chromium.cjs');
if (!args.page || !args.out) {
  console.error('usage: drive_page.cjs --page drive/index.html --out DIR [--frame K] [--take FILE] [--webcam Y4M --seconds S] [--video WEBM --fps N]');
  process.exit(2);
}

(async () => {
  fs.mkdirSync(args.out, { recursive: true });
  const flags = [...kChromiumFlags, '--allow-file-access-from-files'];
  if (args.webcam)
    flags.push('--use-fake-ui-for-media-stream', '--use-fake-device-for-media-stream',
               '--use-file-for-fake-video-capture=' + path.resolve(args.webcam));
  const browser = await puppeteer.launch({ executablePath: args.chromium || '/usr/bin/chromium', headless: true,
                                           args: flags, protocolTimeout: 600000 });
  const errors = [];
  let code = 0;
  try {
    const page = await browser.newPage();
    page.on('console', (m) => { if (m.type() === 'error') errors.push(m.text()); });
    page.on('pageerror', (e) => errors.push(String(e)));
    const query = [];
    if (args.frame !== undefined && !args.take) query.push('frame=' + args.frame);
    if (args.webcam) query.push('drive=webcam');
    if (args.video && args.fps) query.push('fps=' + args.fps);
    const url = 'file://' + path.resolve(args.page) + (query.length ? '?' + query.join('&') : '');
    const started = Date.now();
    await page.goto(url, { waitUntil: 'load', timeout: 600000 });
    await page.waitForFunction('window.done === true && window.headforge.mesh !== "loading" || window.headforge && window.headforge.error',
                               { timeout: 600000 });
    const loadSeconds = (Date.now() - started) / 1000;
    if (args.take) {
      const text = fs.readFileSync(args.take, 'utf8');
      await page.evaluate((t, k) => window.headforge.playTake(t, k), text, args.frame === undefined ? null : args.frame);
    }
    if (args.weights) await page.evaluate((w) => window.headforge.setWeights(w), JSON.parse(args.weights));
    if (args.webcam) {
      const seconds = Number(args.seconds || 20);
      await new Promise((r) => setTimeout(r, seconds * 1000));
      // Stopped on a frame with the face found and solved (not in the middle
      // of a loss, not calibrating), so the canvas shows that frame's solve.
      await page.waitForFunction(() => {
        const h = window.headforge, last = h.solves[h.solves.length - 1];
        if (h.lost_seconds !== 0 || !last || last.calibrating) return false;
        h.stopWebcam();
        return true;
      }, { timeout: 60000, polling: 'raf' }).catch(() => page.evaluate(() => window.headforge.stopWebcam()));
    } else if (args.video) {
      // As a user gives it: the file chosen in the page's file input.
      const input = await page.$('#open');
      await input.uploadFile(path.resolve(args.video));
      // Polled from here (a long video in a software renderer takes longer
      // than one protocol call may wait), its progress said every 30 s.
      const limit = Date.now() + 1000 * Number(args['video-timeout'] || 7200);
      let said = Date.now();
      for (;;) {
        const at = await page.evaluate(() => ({ done: window.headforge.video_done === true, frame: window.headforge.video_frame,
                                                frames: window.headforge.video_frames }));
        if (at.done) break;
        if (Date.now() > limit) throw new Error('the video was not done within --video-timeout');
        if (Date.now() - said > 30000) {
          console.log(`drive page: video frame ${at.frame + 1} of ${at.frames}`);
          said = Date.now();
        }
        await new Promise((r) => setTimeout(r, 1000));
      }
    } else if (!args.take && args.frame === undefined) {
      await new Promise((r) => setTimeout(r, 3000));  // a few frames of the looped take, for the frame rate
    }
    const state = await page.evaluate(() => {
      const h = window.headforge;
      return { mode: h.mode, mesh: h.mesh, frame: h.frame, fps: h.fps, ms_pose: h.ms_pose, ms_sort: h.ms_sort, ms_gl: h.ms_gl, drawn: h.drawn, halfFloat: h.halfFloat, error: h.error,
               unknown: h.unknown || [], lost_seconds: h.lost_seconds, lost_episodes: h.lost_episodes,
               weights: Array.from(h.weights), names: h.names,
               cam_from_head: Array.from(h.camFromHead), solves: h.solves, stream_started: h.stream_started,
               video_frames: h.video_frames, status: h.status };
    });
    const png = await page.evaluate(() => document.getElementById('view').toDataURL('image/png'));
    fs.writeFileSync(path.join(args.out, 'canvas.png'), Buffer.from(png.split(',')[1], 'base64'));
    if (state.mesh === 'drawn') {
      // PlayCanvas draws the mesh on its own frame: one more, after the last change.
      await page.evaluate(() => new Promise((r) => requestAnimationFrame(() => requestAnimationFrame(r))));
      const meshPng = await page.evaluate(() => document.getElementById('mesh-view').toDataURL('image/png'));
      fs.writeFileSync(path.join(args.out, 'mesh.png'), Buffer.from(meshPng.split(',')[1], 'base64'));
    }
    if (args.compare) {
      const dataUrl = (file) => 'data:image/png;base64,' + fs.readFileSync(file).toString('base64');
      state.compare = await page.evaluate(comparePixels, [png, dataUrl(args.compare), dataUrl(args.mask)]);
      state.compare.min_psnr = Number(args['min-psnr'] || 28);
    }
    state.errors = errors;
    state.load_seconds = loadSeconds;
    state.user_agent = await browser.version();
    fs.writeFileSync(path.join(args.out, 'state.json'), JSON.stringify(state));
    console.log(`drive page: ${state.mode}, frame ${state.frame}, ${state.drawn} frames drawn, ` +
                `${state.fps.toFixed(1)} frames/s (last frame: pose ${state.ms_pose.toFixed(1)} ms, sort ` +
                `${state.ms_sort.toFixed(1)} ms, WebGL ${state.ms_gl.toFixed(1)} ms), ${state.solves.length} solves from a face, loaded in ${loadSeconds.toFixed(1)} s`);
    if (state.compare) {
      console.log(`drive page against ${path.basename(args.compare)}: ${state.compare.psnr.toFixed(2)} dB over ` +
                  `${state.compare.count} px of head`);
      if (!(state.compare.count > 0 && state.compare.psnr >= state.compare.min_psnr)) code = 1;
    }
    if (errors.length || state.error) {
      console.error('drive page errors: ' + JSON.stringify(errors) + ' ' + (state.error || ''));
      code = 1;
    }
  } catch (e) {
    console.error('drive page: ' + e + (errors.length ? ' (console: ' + errors.join('; ') + ')' : ''));
    code = 1;
  } finally {
    await browser.close();
  }
  process.exit(code);
})();
