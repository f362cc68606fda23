// The drive page (export --formats drive): the Gaussian avatar's linear
// blendshapes posed every frame by 53 expression weights and a head pose,
// from one of three sources:
//   - a recorded take: the capture's own tracking (the default, looped;
//     ?frame=K holds frame K), or a file given to the page (a Live Link Face
//     CSV of ARKit weights, or a workspace's tracking.json);
//   - the webcam (?drive=webcam or the button): MediaPipe's face mesh in the
//     page (TensorFlow.js), the weights and pose solved against the face
//     model's 468 points (face_drive.js);
//   - a recorded video of a face (given to the page as a file): the same,
//     every frame in turn, paced by the video's time;
//   - a script: window.headforge.setWeights(...).
// window.headforge exposes what is shown (weights, pose, frame rate) to
// scripts; window.done is set once the first frame is drawn.
(function () {
  const data = JSON.parse(document.getElementById('drive-data').textContent);
  const params = new URLSearchParams(location.search);
  const names = data.names, k = names.length, n = data.gaussians;

  const bytesOf = (id) => {
    const text = atob(document.getElementById(id).textContent.trim());
    const bytes = new Uint8Array(text.length);
    for (let i = 0; i < text.length; ++i) bytes[i] = text.charCodeAt(i);
    return bytes.buffer;
  };
  const halfToFloat = (half) => {
    const out = new Float32Array(half.length);
    for (let i = 0; i < half.length; ++i) {
      const h = half[i], sign = h & 0x8000 ? -1 : 1, e = (h >> 10) & 0x1f, m = h & 0x3ff;
      out[i] = sign * (e === 0 ? m * 5.960464477539063e-8 : e === 31 ? (m ? NaN : Infinity) : (1 + m / 1024) * 2 ** (e - 15));
    }
    return out;
  };
  // blendshapes.bin's layout: opacities [N], neutral [N, 13], offsets [K, N, 13].
  const raw = bytesOf('blendshapes');
  const opacities = new Float32Array(raw, 0, n);
  const neutral = new Float32Array(raw, 4 * n, 13 * n);
  const offsets = data.offsets_type === 'float16' ? halfToFloat(new Uint16Array(raw, 56 * n, 13 * n * k))
                                                  : new Float32Array(raw, 56 * n, 13 * n * k);
  const attributes = new Float32Array(13 * n);
  const pose = (weights) => {
    attributes.set(neutral);
    for (let e = 0; e < k; ++e) {
      const w = weights[e];
      if (Math.abs(w) < 1e-5) continue;
      const shape = offsets.subarray(13 * n * e, 13 * n * (e + 1));
      for (let j = 0; j < 13 * n; ++j) attributes[j] += w * shape[j];
    }
    return attributes;
  };

  const canvas = document.getElementById('view');
  const renderer = HeadforgeSplatGL.create(canvas, data.camera.width, data.camera.height, data.background);
  const firstPose = data.frames.length ? data.frames[0].cam_from_head : [1, 0, 0, 0, 0, -1, 0, 0, 0, 0, -1, 0.6];
  const state = {
    names, weights: new Float32Array(k), camFromHead: Float64Array.from(firstPose),
    mode: 'take', frame: -1, fps: 0, drawn: 0, solves: [], lost_seconds: 0, lost_episodes: [], error: null,
    halfFloat: renderer.halfFloat,
    mesh: document.getElementById('mesh-glb') ? 'loading' : 'none',
  };
  window.headforge = state;

  // The mesh avatar beside the Gaussians (where the page holds it): PlayCanvas
  // draws its glTF, the morph targets set by the same weights, through the
  // same camera (the head's node held still: the pose is the camera's).
  const mesh = (() => {
    const block = document.getElementById('mesh-glb');
    if (!block || typeof pc === 'undefined') return null;
    const canvas = document.getElementById('mesh-view');
    canvas.hidden = false;
    const app = new pc.Application(canvas, { graphicsDeviceOptions: { antialias: true, preserveDrawingBuffer: true } });
    app.setCanvasResolution(pc.RESOLUTION_FIXED, data.camera.width, data.camera.height);
    // Drawn when the pose or the weights change, not every animation frame
    // (in a software renderer that would take the time the face mesh needs).
    app.autoRender = false;
    app.start();
    const camera = new pc.Entity('camera');
    camera.addComponent('camera', { clearColor: new pc.Color(data.background, data.background, data.background), nearClip: 0.01,
                                    farClip: 50 });
    // The pinhole's projection, principal point included (pixel centres at integers).
    const c = data.camera, near = 0.01, far = 50;
    camera.camera.calculateProjection = (m) => {
      m.data.fill(0);
      m.data[0] = 2 * c.fx / c.width;
      m.data[5] = 2 * c.fy / c.height;
      m.data[8] = 1 - 2 * (c.cx + 0.5) / c.width;
      m.data[9] = 2 * (c.cy + 0.5) / c.height - 1;
      m.data[10] = -(far + near) / (far - near);
      m.data[11] = -1;
      m.data[14] = -2 * far * near / (far - near);
    };
    app.root.addChild(camera);
    const light = new pc.Entity('light');
    light.addComponent('light', { type: 'directional', intensity: 0.6 });
    camera.addChild(light);
    const rig = { morph: null, index: null };
    const asset = new pc.Asset('mesh', 'container', { url: URL.createObjectURL(new Blob([bytesOf('mesh-glb')])), filename: 'mesh.glb' });
    asset.on('load', () => {
      const entity = asset.resource.instantiateRenderEntity();
      app.root.addChild(entity);
      const instance = entity.findComponents('render').flatMap((r) => r.meshInstances).find((m) => m.morphInstance);
      if (!instance) { window.headforge.error = 'mesh: the glTF has no morph targets'; return; }
      rig.morph = instance.morphInstance;
      const byName = new Map(instance.morphInstance.morph.targets.map((t, i) => [canonical(t.name), i]));
      rig.index = names.map((name) => byName.get(canonical(name)));
      place(window.headforge.weights, window.headforge.camFromHead);
      // Drawn on PlayCanvas's next frame.
      app.once('frameend', () => { window.headforge.mesh = 'drawn'; });
    });
    asset.on('error', (e) => { window.headforge.error = 'mesh: ' + e; });
    app.assets.add(asset);
    app.assets.load(asset);
    // OpenCV's camera (x right, y down, looking along +z) as PlayCanvas's
    // (looking along -z, y up): its axes in the head frame are R's rows.
    const place = (weights, p) => {
      const centre = [0, 1, 2].map((j) => -(p[j] * p[3] + p[4 + j] * p[7] + p[8 + j] * p[11]));
      const m = new pc.Mat4();
      m.data.set([p[0], p[1], p[2], 0, -p[4], -p[5], -p[6], 0, -p[8], -p[9], -p[10], 0, centre[0], centre[1], centre[2], 1]);
      camera.setPosition(centre[0], centre[1], centre[2]);
      camera.setRotation(new pc.Quat().setFromMat4(m));
      if (rig.morph) rig.index.forEach((target, i) => { if (target !== undefined) rig.morph.setWeight(target, weights[i]); });
      app.renderNextFrame = true;
    };
    return { place };
  })();

  // Frame rate over the last second of drawn frames.
  const stamps = [];
  const draw = () => {
    const start = performance.now();
    const posed = pose(state.weights);
    const posedAt = performance.now();
    const times = renderer.draw(posed, opacities, state.camFromHead, data.camera);
    if (mesh) mesh.place(state.weights, state.camFromHead);
    const now = performance.now();
    // Milliseconds of the last frame: the weighted sum, the Gaussians in the
    // camera's frame sorted by depth, and WebGL's drawing.
    state.ms_pose = posedAt - start;
    state.ms_sort = times.ms_sort;
    state.ms_gl = times.ms_gl;
    stamps.push(now);
    while (stamps.length > 1 && now - stamps[0] > 1000) stamps.shift();
    state.fps = stamps.length > 1 ? (stamps.length - 1) * 1000 / (now - stamps[0]) : 0;
    ++state.drawn;
    showWeights();
    if (!window.done) window.done = true;
  };

  // The legend: the strongest weights as bars, the source and frame rate.
  const panel = document.getElementById('weights');
  const showWeights = () => {
    const top = Array.from(state.weights, (w, i) => [w, i]).sort((a, b) => b[0] - a[0]).slice(0, 8);
    panel.textContent = '';
    const head = document.createElement('div');
    head.textContent = state.mode + (state.frame >= 0 ? ' frame ' + state.frame : '') +
                       ((state.mode === 'webcam' || state.mode === 'video') && state.status ? ' (' + state.status + ')' : '') + ' · ' +
                       state.fps.toFixed(1) + ' frames/s';
    panel.appendChild(head);
    for (const [w, i] of top) {
      const row = document.createElement('div');
      row.className = 'bar';
      row.style.setProperty('--w', Math.max(0, Math.min(1, w)));
      row.textContent = names[i] + ' ' + w.toFixed(2);
      panel.appendChild(row);
    }
  };

  // A take: frames of weights (by the avatar's names) and, for the capture's
  // own, its camera-from-head poses.
  let take = data.frames.map((f) => ({ frame: f.frame, weights: f.weights, cam_from_head: f.cam_from_head }));
  let playing = null;
  const showTakeFrame = (index) => {
    const f = take[index];
    state.frame = f.frame;
    state.weights.set(f.weights);
    state.camFromHead.set(f.cam_from_head || firstPose);
    draw();
  };
  const play = (frames, label, hold) => {
    stopWebcam();
    playing = null;
    take = frames;
    state.mode = label;
    if (!take.length) throw new Error('the take has no frames');
    if (hold !== undefined && hold !== null) {
      const index = take.findIndex((f) => f.frame === Number(hold));
      if (index < 0) throw new Error('the take has no frame ' + hold);
      showTakeFrame(index);
      return;
    }
    // Each animation frame shows the take's frame whose time has come, posed
    // and drawn only when that frame changes (frames are skipped when
    // drawing is slower than the take).
    const session = {};
    playing = session;
    const started = performance.now();
    let shown = -1;
    const next = () => {
      if (playing !== session) return;
      const index = Math.floor((performance.now() - started) / 1000 * data.fps) % take.length;
      if (index !== shown) showTakeFrame((shown = index));
      requestAnimationFrame(next);
    };
    next();
  };

  // A name of another rig's blendshape in the avatar's: ARKit's
  // "EyeBlinkLeft" (Live Link Face) or "eyeBlinkLeft" is "eyeBlink_L".
  const canonical = (name) => name.toLowerCase().replace(/(_l|left)$/, '<l').replace(/(_r|right)$/, '<r').replace(/_/g, '');
  const byCanonical = new Map(names.map((name, i) => [canonical(name), i]));
  // Parses a Live Link Face CSV or a tracking.json into a take: weights
  // outside [0, 1] are clamped, blendshapes the take lacks stay 0, and the
  // names it has that the avatar lacks are reported in state.unknown.
  const weightsFrom = (pairs, unknown) => {
    const weights = new Float32Array(k);
    for (const [name, value] of pairs) {
      // ARKit's browInnerUp and cheekPuff are one blendshape where the face
      // model has a left and a right one: both take its weight.
      const c = canonical(name);
      const targets = byCanonical.has(c) ? [byCanonical.get(c)]
                                         : [byCanonical.get(c + '<l'), byCanonical.get(c + '<r')].filter((i) => i !== undefined);
      if (!targets.length) { if (unknown) unknown.add(name); continue; }
      const v = Number(value);
      for (const i of targets) weights[i] = Number.isFinite(v) ? Math.min(1, Math.max(0, v)) : 0;
    }
    return weights;
  };
  const parseTake = (text) => {
    const trimmed = text.trim();
    const frames = [], unknown = new Set();
    if (trimmed.startsWith('{')) {
      const tracking = JSON.parse(trimmed);
      for (const f of tracking.frames || []) frames.push({ frame: f.frame, weights: weightsFrom(Object.entries(f.expression || {}), unknown) });
    } else {
      const lines = trimmed.split(/\r?\n/);
      const header = lines[0].split(',').map((s) => s.trim());
      const skip = new Set(['timecode', 'blendshapecount']);
      const head = /^(head|lefteye|righteye)(yaw|pitch|roll)$/;
      for (let row = 1; row < lines.length; ++row) {
        const cells = lines[row].split(',');
        if (cells.length < header.length) continue;
        const pairs = [];
        header.forEach((name, i) => {
          const low = name.toLowerCase();
          if (!skip.has(low) && !head.test(low)) pairs.push([name, cells[i]]);
        });
        frames.push({ frame: row - 1, weights: weightsFrom(pairs, unknown) });
      }
    }
    state.unknown = Array.from(unknown);
    return frames;
  };
  state.playTake = (text, hold) => play(parseTake(text), 'recorded take', hold);
  state.setWeights = (weights) => {
    stopWebcam();
    playing = null;
    state.mode = 'script';
    state.frame = -1;
    if (Array.isArray(weights) || ArrayBuffer.isView(weights)) state.weights.set(weights);
    else state.weights.set(weightsFrom(Object.entries(weights)));
    draw();
  };

  // The webcam: the face mesh found in each frame, the weights and pose
  // solved against the face model's points. The first frames calibrate: the
  // driver holds a neutral face while the model's points are moved to where
  // the face mesh puts them on that face (another person's face, and the
  // mesh's own placement of its points); ?calibrate=N frames (10; 0: none).
  // A face lost for more than half a second eases the avatar back to its
  // rest over a second.
  let webcam = null;
  function stopWebcam() {
    if (!webcam) return;
    webcam.stop = true;
    if (webcam.stream) webcam.stream.getTracks().forEach((t) => t.stop());
    webcam = null;
  }
  const thumbnail = (image) => {
    // 8 x 8 grey means of the frame: which frame a result belongs to.
    const out = [];
    for (let by = 0; by < 8; ++by)
      for (let bx = 0; bx < 8; ++bx) {
        let sum = 0, count = 0;
        for (let y = Math.floor(by * image.height / 8); y < Math.floor((by + 1) * image.height / 8); y += 2)
          for (let x = Math.floor(bx * image.width / 8); x < Math.floor((bx + 1) * image.width / 8); x += 2) {
            const p = 4 * (y * image.width + x);
            sum += image.data[p] + image.data[p + 1] + image.data[p + 2];
            count += 3;
          }
        out.push(sum / Math.max(1, count));
      }
    return out;
  };
  const calibrationFrames = Number(params.get('calibrate') ?? 10);
  // The avatar's rest: the capture's first frame, its expression and pose.
  const rest = { weights: data.frames.length ? Float64Array.from(data.frames[0].weights) : new Float64Array(k),
                 pose: Float64Array.from(firstPose) };
  // Poses as row-major 3 x 4 [R | t]: a * b, and a's inverse.
  const compose = (a, b) => {
    const out = new Float64Array(12);
    for (let i = 0; i < 3; ++i) {
      for (let j = 0; j < 4; ++j)
        out[4 * i + j] = a[4 * i] * b[j] + a[4 * i + 1] * b[4 + j] + a[4 * i + 2] * b[8 + j];
      out[4 * i + 3] += a[4 * i + 3];
    }
    return out;
  };
  const invert = (a) => {
    const out = new Float64Array(12);
    for (let i = 0; i < 3; ++i) {
      for (let j = 0; j < 3; ++j) out[4 * i + j] = a[4 * j + i];
      out[4 * i + 3] = -(a[i] * a[3] + a[4 + i] * a[7] + a[8 + i] * a[11]);
    }
    return out;
  };
  const poseOf = (fit) => {
    const r = fit.rotation, t = fit.translation;
    return Float64Array.from([r[0], r[1], r[2], t[0], r[3], r[4], r[5], t[1], r[6], r[7], r[8], t[2]]);
  };
  // The calibration frames' mean pose (rotations averaged as matrices and
  // made orthonormal again by a few polar iterations).
  const meanPose = (fits) => {
    const m = new Float64Array(12);
    for (const fit of fits) poseOf(fit).forEach((v, i) => { m[i] += v / fits.length; });
    for (let iteration = 0; iteration < 8; ++iteration) {
      // R <- (R + R^-T) / 2; R^-T is R's cofactor matrix over its determinant.
      const det = m[0] * (m[5] * m[10] - m[6] * m[9]) - m[1] * (m[4] * m[10] - m[6] * m[8]) + m[2] * (m[4] * m[9] - m[5] * m[8]);
      const cof = [m[5] * m[10] - m[6] * m[9], m[6] * m[8] - m[4] * m[10], m[4] * m[9] - m[5] * m[8],
                   m[2] * m[9] - m[1] * m[10], m[0] * m[10] - m[2] * m[8], m[1] * m[8] - m[0] * m[9],
                   m[1] * m[6] - m[2] * m[5], m[2] * m[4] - m[0] * m[6], m[0] * m[5] - m[1] * m[4]];
      for (let i = 0; i < 3; ++i)
        for (let j = 0; j < 3; ++j) m[4 * i + j] = 0.5 * (m[4 * i + j] + cof[3 * i + j] / det);
    }
    return m;
  };
  // The basis weighted toward the points expressions hardly move (the
  // third of the points whose largest offset is smallest; the rest at 0.05):
  // the head's pose from them first, then the expression with the pose held
  // close, so an expression is not taken for a turn of the head.
  const rigidBasis = (basis) => {
    const reach = basis.neutral.map((_, i) => Math.max(...basis.offsets.map((o) => Math.hypot(...o[i]))));
    const cut = [...reach].sort((a, b) => a - b)[Math.floor(reach.length / 3)];
    return Object.assign({}, basis, { pointWeights: reach.map((r) => (r <= cut ? 1 : 0.05)) });
  };
  // A frame after calibration: the pose from the rigid points, then the
  // expression with the pose held close; `scale` weakens the pull toward
  // `previous` (1: the frame just before).
  const solveLive = (session, points, camera, previous, scale) => {
    const d = HeadforgeFaceDrive.kSolveDefaults, iterations = scale < 0.5 ? 3 * d.iterations : d.iterations;
    const head = HeadforgeFaceDrive.solveFace(points, session.rigid, camera, previous, {
      poseOnly: true, temporalRotation: d.temporalRotation * scale, temporalTranslation: d.temporalTranslation * scale,
      iterations });
    return HeadforgeFaceDrive.solveFace(points, session.basis, camera,
                                        { rotation: head.rotation, translation: head.translation,
                                          weights: previous ? previous.weights : rest.weights },
                                        { temporalWeights: d.temporalWeights * scale, temporalRotation: 100 * d.temporalRotation,
                                          temporalTranslation: 100 * d.temporalTranslation, iterations,
                                          expressionPrior: data.face.expression_prior || null });
  };
  // One frame's solve. The first frames calibrate: the driver is taken to
  // hold the avatar's rest (its expression and its pose in its camera): the
  // face model's points are moved to where the face mesh puts them on the
  // driver's face at that expression, and the head's motion is measured
  // from the pose held then and placed on the avatar's rest pose. So another
  // face, the face mesh's own placement of its points and another camera's
  // distance start the avatar where its capture started.
  const solveFrame = (session, points, camera, at) => {
    // The calibration's frames come from one still moment: frames grabbed
    // (`at`) more than a second and a half apart start it again.
    if (session.calibration.length && session.calibration.length < calibrationFrames &&
        at - session.calibratedAt > 1500) {
      session.calibration = [];
      session.previous = null;
    }
    session.calibratedAt = at;
    if (session.calibration.length < calibrationFrames) {
      const guess = HeadforgeFaceDrive.solveFace(points, session.basis, camera, session.previous, { poseOnly: true });
      const fit = HeadforgeFaceDrive.solveFace(points, session.basis, camera,
                                               { rotation: guess.rotation, translation: guess.translation,
                                                 weights: rest.weights }, { poseOnly: true });
      session.previous = fit;
      session.calibration.push([Float32Array.from(points), fit]);
      state.status = 'hold still, as the avatar looks: ' + session.calibration.length + ' of ' + calibrationFrames;
      if (session.calibration.length === calibrationFrames) {
        const fits = session.calibration.map((c) => c[1]);
        session.basis = HeadforgeFaceDrive.calibrateNeutral(session.calibration.map((c) => c[0]), data.face, camera, fits);
        session.rigid = rigidBasis(session.basis);
        // The rest pose as the live solve sees it: the calibration frames
        // solved again with the expression free.
        let previous = null;
        const free = session.calibration.map(([p]) => (previous = solveLive(session, p, camera, previous, 1)));
        session.toAvatar = compose(invert(meanPose(free)), rest.pose);
        session.previous = null;
        state.status = 'calibrated';
      }
      return { weights: rest.weights, pose: rest.pose, fit, calibrating: true };
    }
    // The pull toward the previous frame weakens with the time since it
    // (a slow page sees frames far apart), and a stale start gets more steps.
    const scale = session.previous ? Math.min(1, 1000 / 30 / Math.max(1, at - session.previousAt)) : 1;
    const fit = solveLive(session, points, camera, session.previous, scale);
    session.previous = fit;
    session.previousAt = at;
    return { weights: fit.weights, pose: session.toAvatar ? compose(poseOf(fit), session.toAvatar) : poseOf(fit), fit,
             calibrating: false };
  };
  // The face mesh network, loaded once. Its first runs compile its programs
  // (seconds in a software renderer): done before the first frame, not on
  // the calibration's.
  let trackerLoaded = null;
  const loadTracker = () => trackerLoaded || (trackerLoaded = (async () => {
    const model = await HeadforgeFaceDrive.loadFaceMesh(tf, JSON.parse(document.getElementById('facemesh-json').textContent),
                                                         bytesOf('facemesh-bin'));
    const tracker = new HeadforgeFaceDrive.FaceMeshTracker(tf, model);
    const blank = { data: new Uint8ClampedArray(4 * 64 * 64), width: 64, height: 64 };
    const squares = HeadforgeFaceDrive.searchRegions(64, 64);
    await tracker.predict(blank, squares);
    await tracker.predict(blank, squares.slice(0, 1));
    return tracker;
  })());
  // A driving session (the webcam's or a video's), reset by ?recalibrate.
  const startSession = async (mode) => {
    if (!data.face || typeof tf === 'undefined') throw new Error('this page has no face mesh model: export it with the vision models installed (scripts/install_deps.sh)');
    stopWebcam();
    playing = null;
    state.mode = mode;
    state.frame = -1;
    state.solves = [];
    state.lost_episodes = [];
    state.error = null;
    const session = { stop: false, basis: data.face, calibration: [], previous: null, lostSince: null,
                      searchedAt: -Infinity, calibrationDrawn: false, lostEpisode: null };
    webcam = session;
    state.recalibrate = () => { session.basis = data.face; session.calibration = []; session.previous = null; session.toAvatar = null; };
    session.tracker = await loadTracker();
    session.tracker.reset();
    return session;
  };
  // One frame of a session: the face found (while it is lost, searched for
  // at most five times a second of the frames' time `at`, in ms), the
  // weights and pose solved, the avatar drawn. `extra` goes into the solve's
  // record (a video's frame number).
  const driveImage = async (session, image, at, extra) => {
    let found = { found: false };
    const start = performance.now();
    if (session.lostSince === null || at - session.searchedAt >= 200) {
      if (session.lostSince !== null) session.searchedAt = at;
      found = await session.tracker.track(image);
    }
    const now = performance.now();
    if (found.found) {
      const solved = solveFrame(session, found.points, scaledCamera(data.face.camera, image.width, image.height), at);
      session.lostSince = null;
      state.lost_seconds = 0;
      state.weights.set(solved.weights);
      state.camFromHead.set(solved.pose);
      state.solves.push(Object.assign({ thumb: thumbnail(image), weights: Array.from(solved.weights),
                                        cam_from_head: Array.from(solved.pose), residual_px: solved.fit.residual_px,
                                        calibrating: solved.calibrating, at,
                                        ms_network: now - start, ms_solve: performance.now() - now }, extra));
      if (state.solves.length > 2000) state.solves.shift();
    } else {
      // Hold, then ease back to rest.
      if (session.lostSince === null) session.lostSince = session.searchedAt = at;
      state.lost_seconds = (at - session.lostSince) / 1000;
      session.previous = null;
      if (state.lost_seconds > 0.5) {
        const a = Math.min(1, (state.lost_seconds - 0.5) / 1.0);
        for (let i = 0; i < k; ++i) state.weights[i] += (rest.weights[i] - state.weights[i]) * a;
        for (let i = 0; i < 12; ++i) state.camFromHead[i] += (rest.pose[i] - state.camFromHead[i]) * a;
      }
      // The episode as scripts see it: how long, and how far from rest the avatar still is.
      let off = 0;
      for (let i = 0; i < k; ++i) off = Math.max(off, Math.abs(state.weights[i] - rest.weights[i]));
      for (let i = 0; i < 12; ++i) off = Math.max(off, Math.abs(state.camFromHead[i] - rest.pose[i]));
      session.lostEpisode = { seconds: state.lost_seconds, off_rest: off, solves_before: state.solves.length };
    }
    if (found.found && session.lostEpisode) {
      state.lost_episodes.push(session.lostEpisode);
      session.lostEpisode = null;
    }
    // While calibrating the avatar holds its rest: drawn once.
    const calibrating = found.found && state.solves[state.solves.length - 1].calibrating;
    if (!(calibrating && session.calibrationDrawn)) draw();
    session.calibrationDrawn = calibrating;
  };
  const grabber = () => {
    const grab = document.createElement('canvas');
    const context = grab.getContext('2d', { willReadFrequently: true });
    return (video) => {
      grab.width = video.videoWidth;
      grab.height = video.videoHeight;
      context.drawImage(video, 0, 0, grab.width, grab.height);
      return context.getImageData(0, 0, grab.width, grab.height);
    };
  };
  const startWebcam = async () => {
    const session = await startSession('webcam');
    // The camera's own size: a size asked for may be cropped or scaled from
    // it, which the solve's camera (the capture's, at the frame's size) would not know.
    session.stream = await navigator.mediaDevices.getUserMedia({ video: true, audio: false });
    const video = document.createElement('video');
    video.muted = true;
    video.playsInline = true;
    video.srcObject = session.stream;
    await video.play();
    state.stream_started = performance.now();
    const grab = grabber();
    while (!session.stop) {
      if (!video.videoWidth || !video.videoHeight) { await new Promise((r) => setTimeout(r, 30)); continue; }
      const image = grab(video);
      await driveImage(session, image, performance.now());
      await new Promise((r) => requestAnimationFrame(r));
    }
  };
  // A recorded video (a file the page is given) drives the avatar as the
  // webcam does, every frame of it (sampled ?fps=N times a second of the
  // video, 25) in turn, however long each takes: the video's time, not the
  // clock's, paces the solve. state.video_frame and state.video_frames say
  // how far it is; state.video_done when it has ended.
  const startVideo = async (file) => {
    const session = await startSession('video');
    state.video_done = false;
    const video = document.createElement('video');
    video.muted = true;
    video.preload = 'auto';
    const url = URL.createObjectURL(file);
    session.stream = { getTracks: () => [{ stop: () => URL.revokeObjectURL(url) }] };
    await new Promise((resolve, reject) => {
      video.onloadeddata = resolve;
      video.onerror = () => reject(new Error('cannot decode ' + (file.name || 'the video') + ': ' +
                                            (video.error ? video.error.message || 'code ' + video.error.code : 'unknown')));
      video.src = url;
    });
    const fps = Number(params.get('fps') || 25);
    const count = Math.max(1, Math.floor(video.duration * fps + 1e-6));
    state.video_frames = count;
    const grab = grabber();
    for (let i = 0; i < count && !session.stop; ++i) {
      await new Promise((resolve) => {
        video.onseeked = resolve;
        video.currentTime = i / fps + 0.002;  // the frame shown from that time on
      });
      state.video_frame = i;
      state.status = 'frame ' + (i + 1) + ' of ' + count;
      await driveImage(session, grab(video), 1000 * i / fps, { video_frame: i });
    }
    if (!session.stop) state.status = 'the video has ended';
    state.video_done = true;
  };
  // The capture's camera at another image size (the webcam's): the same
  // field of view along the longer side, centred.
  const scaledCamera = (c, w, h) => {
    const s = Math.max(w, h) / Math.max(c.width, c.height);
    const same = Math.abs(w / h - c.width / c.height) < 1e-3;
    return { fx: c.fx * s, fy: c.fy * s, cx: same ? (c.cx + 0.5) * s - 0.5 : (w - 1) / 2,
             cy: same ? (c.cy + 0.5) * s - 0.5 : (h - 1) / 2, width: w, height: h };
  };
  state.startWebcam = () => startWebcam().catch((e) => { state.error = String(e); console.error('drive: ' + e); });
  state.startVideo = (file) => startVideo(file).catch((e) => {
    state.error = String(e);
    state.video_done = true;
    console.error('drive: ' + e);
  });
  state.stopWebcam = stopWebcam;

  document.getElementById('webcam').onclick = state.startWebcam;
  document.getElementById('replay').onclick = () => play(data.frames, 'the capture\'s take');
  document.getElementById('open').onchange = async (event) => {
    const file = event.target.files[0];
    if (!file) return;
    if (file.type.startsWith('video/') || /\.(webm|mp4|m4v|mov|mkv|ogv)$/i.test(file.name)) state.startVideo(file);
    else state.playTake(await file.text());
  };
  if (!data.face || typeof tf === 'undefined') document.getElementById('webcam').disabled = true;

  if (params.get('drive') === 'webcam') state.startWebcam();
  else if (data.frames.length) play(data.frames, 'the capture\'s take', params.get('frame'));
  else draw();
})();
