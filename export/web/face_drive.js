// Webcam -> expression weights and head pose for the drive page (written by
// `headforge export --formats drive`). Two parts:
//  - FaceMeshTracker: MediaPipe's face mesh (468 points; facemesh.json, run by
//    TensorFlow.js) followed from frame to frame, with the region geometry of
//    vision/face_mesh.cc.
//  - solveFace: the head pose in the camera frame and the 53 expression
//    weights whose projected model points best match the tracked points
//    (damped Gauss-Newton, weights bounded to [0, 1]); calibrateNeutral
//    fits the basis' neutral to whoever drives, from a few neutral frames.
// A plain script: inlined into the page, or require()d by node
// (scripts/web/face_drive_check.cjs).
const HeadforgeFaceDrive = (() => {
  const kInputSize = 192;
  const kPoints = 468;
  // MediaPipe's face oval (FACEMESH_FACE_OVAL): points that slide along the
  // silhouette as the head turns.
  const kFaceOval = [10, 338, 297, 332, 284, 251, 389, 356, 454, 323, 361, 288, 397, 365, 379, 378, 400, 377,
                     152, 148, 176, 149, 150, 136, 172, 58, 132, 93, 234, 127, 162, 21, 54, 103, 67, 109];

  // ---------------------------------------------------------------- regions

  // A square region of the image: centre (pixel centres at integers), side
  // (pixels) and angle (radians; the region's +x axis in the image).
  function region(cx, cy, side, angle) {
    return { centre: [cx, cy], side, angle: angle || 0 };
  }

  // Region -> image: image = centre + k R (p - size / 2), p a position in the
  // network's square (its pixel i spans [i, i + 1]), k = side / size.
  // Returns the 2x3 affine [a, b, c, d, e, f]: x = a p.x + b p.y + c, y = d p.x + e p.y + f.
  function regionToImage(r, size) {
    const k = r.side / size, c = Math.cos(r.angle) * k, s = Math.sin(r.angle) * k, h = size / 2;
    return [c, -s, r.centre[0] - c * h + s * h, s, c, r.centre[1] - s * h - c * h];
  }

  // MediaPipe's rule: the points' bounding box, 1.5 times its longer side,
  // turned by the line through points 33 and 263 (the eyes' outer corners).
  function regionFromMesh(points) {
    let x0 = Infinity, y0 = Infinity, x1 = -Infinity, y1 = -Infinity;
    for (let i = 0; i < kPoints; i++) {
      const x = points[3 * i], y = points[3 * i + 1];
      if (x < x0) x0 = x;
      if (x > x1) x1 = x;
      if (y < y0) y0 = y;
      if (y > y1) y1 = y;
    }
    const angle = Math.atan2(points[3 * 263 + 1] - points[3 * 33 + 1], points[3 * 263] - points[3 * 33]);
    return region((x0 + x1) / 2, (y0 + y1) / 2, Math.max(x1 - x0, y1 - y0) * 1.5, angle);
  }

  // Squares tried when no face is followed (no detector on the page), 13 in
  // all: the frame's centred square at sides 1, 0.75, 0.55 and 0.4 of its
  // shorter side, the smaller ones also shifted sideways and up, where a face
  // in a webcam frame usually is. The network finds a face over about a 1.5x
  // range of sizes around each side, so a face from about 0.2 to 0.7 of the
  // frame's height is found.
  function searchRegions(width, height) {
    const m = Math.min(width, height), cx = (width - 1) / 2, cy = (height - 1) / 2;
    const out = [region(cx, cy, m), region(cx, cy, 0.75 * m), region(cx, cy, 0.55 * m)];
    for (const dx of [-0.22, 0.22]) out.push(region(cx + dx * m, cy, 0.75 * m));
    for (const [dx, dy] of [[-0.25, 0], [0.25, 0], [0, -0.2], [-0.25, -0.2], [0.25, -0.2]])
      out.push(region(cx + dx * m, cy + dy * m, 0.55 * m));
    for (const dx of [-0.3, 0, 0.3]) out.push(region(cx + dx * m, cy - 0.1 * m, 0.4 * m));
    return out;
  }

  // ------------------------------------------------------------------ crop

  // The network's input for region r of frame ({data, width, height}; RGBA
  // or RGB bytes) into out[offset ...]: 192 x 192 RGB in [0, 1], sampled at
  // the square's pixel centres with bilinear interpolation, black outside
  // (cv::warpAffine's INTER_LINEAR, BORDER_CONSTANT 0, on 8-bit pixels: the
  // position is taken to 1/32 pixel and the value rounded, as OpenCV does).
  function cropInto(frame, r, out, offset) {
    const { data, width, height } = frame;
    const ch = data.length / (width * height) >= 4 ? 4 : 3;
    const a = regionToImage(r, kInputSize);
    const s = kInputSize;
    let o = offset;
    for (let j = 0; j < s; j++) {
      const py = j + 0.5;
      for (let i = 0; i < s; i++) {
        const px = i + 0.5;
        const x = Math.round((a[0] * px + a[1] * py + a[2]) * 32) / 32;
        const y = Math.round((a[3] * px + a[4] * py + a[5]) * 32) / 32;
        const xi = Math.floor(x), yi = Math.floor(y), fx = x - xi, fy = y - yi;
        const w00 = (1 - fx) * (1 - fy), w10 = fx * (1 - fy), w01 = (1 - fx) * fy, w11 = fx * fy;
        const in0 = yi >= 0 && yi < height, in1 = yi + 1 >= 0 && yi + 1 < height;
        const i00 = in0 && xi >= 0 && xi < width ? (yi * width + xi) * ch : -1;
        const i10 = in0 && xi + 1 >= 0 && xi + 1 < width ? (yi * width + xi + 1) * ch : -1;
        const i01 = in1 && xi >= 0 && xi < width ? ((yi + 1) * width + xi) * ch : -1;
        const i11 = in1 && xi + 1 >= 0 && xi + 1 < width ? ((yi + 1) * width + xi + 1) * ch : -1;
        for (let c = 0; c < 3; c++) {
          let v = 0;
          if (i00 >= 0) v += w00 * data[i00 + c];
          if (i10 >= 0) v += w10 * data[i10 + c];
          if (i01 >= 0) v += w01 * data[i01 + c];
          if (i11 >= 0) v += w11 * data[i11 + c];
          out[o++] = Math.round(v) / 255;
        }
      }
    }
  }

  // --------------------------------------------------------------- tracker

  // The face mesh graph model from facemesh.json (parsed) and the bytes of
  // facemesh.bin (an ArrayBuffer).
  async function loadFaceMesh(tf, modelJson, weightBytes) {
    const artifacts = {
      modelTopology: modelJson.modelTopology,
      format: modelJson.format,
      generatedBy: modelJson.generatedBy,
      convertedBy: modelJson.convertedBy,
      signature: modelJson.signature,
      weightSpecs: modelJson.weightsManifest.flatMap((g) => g.weights),
      weightData: weightBytes,
    };
    return tf.loadGraphModel(tf.io.fromMemory(artifacts));
  }

  class FaceMeshTracker {
    // tf: the TensorFlow.js module; model: loadFaceMesh's graph model.
    // options.minScore: the face probability below which the face is lost
    // (0.5); options.searchRegions(width, height): the squares tried when no
    // face is followed.
    constructor(tf, model, options = {}) {
      this.tf = tf;
      this.model = model;
      this.minScore = options.minScore !== undefined ? options.minScore : 0.5;
      this.searchRegions = options.searchRegions || searchRegions;
      this.last = null;  // the previous frame's points while a face is followed
      this.stats = { runs: 0, crops: 0, runMs: 0 };
    }

    // Forget the followed face: the next frame searches.
    reset() {
      this.last = null;
    }

    // The mesh in each region of the frame, one network run for all.
    // Returns [{points: Float32Array(468 * 3) (image pixels; z scaled like
    // x and y, nearer smaller), score, region}].
    async predict(frame, regions) {
      const n = regions.length, s = kInputSize;
      const input = new Float32Array(n * s * s * 3);
      regions.forEach((r, i) => cropInto(frame, r, input, i * s * s * 3));
      const t0 = now();
      const x = this.tf.tensor4d(input, [n, s, s, 3]);
      const out = this.model.execute({ input_1: x }, ['output_mesh', 'output_faceflag']);
      const [mesh, flag] = await Promise.all([out[0].data(), out[1].data()]);
      x.dispose();
      out.forEach((t) => t.dispose());
      this.stats.runs++;
      this.stats.crops += n;
      this.stats.runMs += now() - t0;
      return regions.map((r, i) => {
        const a = regionToImage(r, s), k = r.side / s;
        const points = new Float32Array(kPoints * 3);
        for (let j = 0; j < kPoints; j++) {
          const p = i * kPoints * 3 + 3 * j;
          points[3 * j] = a[0] * mesh[p] + a[1] * mesh[p + 1] + a[2];
          points[3 * j + 1] = a[3] * mesh[p] + a[4] * mesh[p + 1] + a[5];
          points[3 * j + 2] = mesh[p + 2] * k;
        }
        return { points, score: flag[i], region: r };
      });
    }

    // The search: every square in one run, then each square that scored a
    // face once more from its own points (a second run). The network also
    // scores part of a face (a mouth and chin) near 1, with points far off;
    // a whole face is a fixed point of the refinement, so the refined square
    // kept is the one whose points moved least (median, over its side) plus
    // a tenth of its refined score's shortfall from 1.
    async search(frame) {
      const tried = await this.predict(frame, this.searchRegions(frame.width, frame.height));
      const hopeful = tried.filter((r) => r.score >= this.minScore);
      if (!hopeful.length) return tried.reduce((a, b) => (b.score > a.score ? b : a));
      const again = await this.predict(frame, hopeful.map((r) => regionFromMesh(r.points)));
      let best = null, bestStrain = Infinity;
      again.forEach((r, i) => {
        if (r.score < this.minScore) return;
        const d = new Float64Array(kPoints);
        for (let j = 0; j < kPoints; j++)
          d[j] = Math.hypot(r.points[3 * j] - hopeful[i].points[3 * j], r.points[3 * j + 1] - hopeful[i].points[3 * j + 1]);
        const strain = d.sort()[kPoints >> 1] / r.region.side + 0.1 * (1 - r.score);
        if (strain < bestStrain) [best, bestStrain] = [r, strain];
      });
      return best || again[0];
    }

    // One frame ({data, width, height}). While a face is followed its square
    // comes from the previous frame's points (one run); otherwise a search
    // (two runs). Returns {points, score, region, found}; found: the face
    // probability is at least minScore (else the next frame searches).
    async track(frame) {
      let best;
      if (this.last) {
        [best] = await this.predict(frame, [regionFromMesh(this.last)]);
      } else {
        best = await this.search(frame);
      }
      const found = best.score >= this.minScore;
      this.last = found ? best.points : null;
      return { points: best.points, score: best.score, region: best.region, found };
    }
  }

  // ----------------------------------------------------------------- solve

  const kPoseUnknowns = 6;  // rotation update (axis-angle, applied on the left), translation

  // The basis packed for the solver (once per basis object): neutral [468 * 3],
  // offsets [468][K][3] (a point's offsets side by side), per-point weights.
  const packed = new WeakMap();
  function packBasis(basis, ovalWeight) {
    let p = packed.get(basis);
    if (p && p.ovalWeight === ovalWeight) return p;
    const K = basis.offsets.length;
    const neutral = new Float64Array(kPoints * 3), offsets = new Float64Array(kPoints * K * 3);
    for (let i = 0; i < kPoints; i++) {
      for (let c = 0; c < 3; c++) neutral[3 * i + c] = basis.neutral[i][c];
      for (let k = 0; k < K; k++)
        for (let c = 0; c < 3; c++) offsets[(i * K + k) * 3 + c] = basis.offsets[k][i][c];
    }
    // basis.pointWeights, where given, weighs the points (e.g. the ones
    // expressions hardly move, for the head's pose alone).
    const weight = basis.pointWeights ? Float64Array.from(basis.pointWeights) : new Float64Array(kPoints).fill(1);
    for (const i of basis.oval || kFaceOval) weight[i] *= ovalWeight;
    const weightSum = weight.reduce((a, b) => a + b, 0);
    p = { K, neutral, offsets, weight, weightSum, ovalWeight, offsetProducts: offsetProducts(offsets, weight, weightSum, K) };
    packed.set(basis, p);
    return p;
  }

  // Coordinate pairs (u, v) of the 3 x 3 symmetric matrices M in addWeightBlock.
  const kPairs = [[0, 0], [1, 1], [2, 2], [0, 1], [0, 2], [1, 2]];

  // G[p][k][l] = sum_i c_i (D_ik[u] D_il[v] + D_ik[v] D_il[u]) / (1 + (u == v))
  // for pair p = (u, v), c_i the points' weights over their sum: [6][K][K],
  // upper triangles.
  function offsetProducts(D, weight, weightSum, K) {
    const G = new Float64Array(6 * K * K);
    for (let i = 0; i < kPoints; i++) {
      const c = weight[i] / weightSum, base = i * K * 3;
      kPairs.forEach(([u, v], p) => {
        for (let k = 0; k < K; k++) {
          const dku = c * D[base + 3 * k + u], dkv = c * D[base + 3 * k + v], row = (p * K + k) * K;
          for (let l = k; l < K; l++) {
            const dl = base + 3 * l;
            G[row + l] += u === v ? dku * D[dl + v] : dku * D[dl + v] + dkv * D[dl + u];
          }
        }
      });
    }
    return G;
  }

  // Model points at weights w, head frame, into X [468 * 3].
  function modelPoints(b, w, X) {
    const K = b.K, D = b.offsets;
    for (let i = 0; i < kPoints; i++) {
      let x = b.neutral[3 * i], y = b.neutral[3 * i + 1], z = b.neutral[3 * i + 2];
      let o = i * K * 3;
      for (let k = 0; k < K; k++, o += 3) {
        const wk = w[k];
        if (wk === 0) continue;
        x += wk * D[o];
        y += wk * D[o + 1];
        z += wk * D[o + 2];
      }
      X[3 * i] = x;
      X[3 * i + 1] = y;
      X[3 * i + 2] = z;
    }
  }

  // The cost of a state {R (9, row-major), t (3), w (K)}: the weighted mean
  // squared pixel residual plus the priors.
  function cost(s, b, pts, cam, prior, o, X) {
    modelPoints(b, s.w, X);
    const R = s.R, t = s.t;
    let data = 0;
    for (let i = 0; i < kPoints; i++) {
      const x = X[3 * i], y = X[3 * i + 1], z = X[3 * i + 2];
      const cx = R[0] * x + R[1] * y + R[2] * z + t[0];
      const cy = R[3] * x + R[4] * y + R[5] * z + t[1];
      const cz = R[6] * x + R[7] * y + R[8] * z + t[2];
      const du = cam.fx * cx / cz + cam.cx - pts[3 * i], dv = cam.fy * cy / cz + cam.cy - pts[3 * i + 1];
      data += b.weight[i] * (du * du + dv * dv);
    }
    return data / b.weightSum + priorCost(s, prior, o);
  }

  function priorCost(s, prior, o) {
    let e = 0;
    const pull = o.pull;
    for (let k = 0; k < s.w.length; k++) e += pull.lambda[k] * (s.w[k] - pull.mean[k]) ** 2;
    if (!prior) return e;
    for (let k = 0; k < s.w.length; k++) e += o.temporalWeights * (s.w[k] - prior.w[k]) ** 2;
    const phi = logRotation(mul3(s.R, transpose3(prior.R)));
    e += o.temporalRotation * dot3(phi, phi);
    for (let c = 0; c < 3; c++) e += o.temporalTranslation * (s.t[c] - prior.t[c]) ** 2;
    return e;
  }

  // The Gauss-Newton normal equations at state s: H (n x n, upper triangle
  // filled) and g (n), over [rotation update, translation, weights], of the
  // data term (weighted mean of squared pixel residuals) and the priors.
  // With poseOnly the weights are held.
  function normalEquations(s, b, pts, cam, prior, o, X, H, g, poseOnly) {
    const K = b.K, n = poseOnly ? kPoseUnknowns : kPoseUnknowns + K, D = b.offsets, R = s.R, t = s.t;
    H.fill(0);
    g.fill(0);
    modelPoints(b, s.w, X);
    const J = new Float64Array(2 * n), M = new Float64Array(6);
    for (let i = 0; i < kPoints; i++) {
      const x = X[3 * i], y = X[3 * i + 1], z = X[3 * i + 2];
      const qx = R[0] * x + R[1] * y + R[2] * z, qy = R[3] * x + R[4] * y + R[5] * z, qz = R[6] * x + R[7] * y + R[8] * z;
      const cx = qx + t[0], cy = qy + t[1], iz = 1 / (qz + t[2]);
      const ru = cam.fx * cx * iz + cam.cx - pts[3 * i], rv = cam.fy * cy * iz + cam.cy - pts[3 * i + 1];
      // d(u, v) / d(camera point): rows a = (fx/z, 0, -fx x/z^2), b = (0, fy/z, -fy y/z^2).
      const a0 = cam.fx * iz, a2 = -cam.fx * cx * iz * iz, b1 = cam.fy * iz, b2 = -cam.fy * cy * iz * iz;
      // Rotation: d(camera point)/d(omega) = -[q]x.
      J[0] = a2 * qy; J[1] = a0 * qz - a2 * qx; J[2] = -a0 * qy;
      J[n] = b2 * qy - b1 * qz; J[n + 1] = -b2 * qx; J[n + 2] = b1 * qx;
      J[3] = a0; J[4] = 0; J[5] = a2;
      J[n + 3] = 0; J[n + 4] = b1; J[n + 5] = b2;
      // Weights: (a R) . offset and (b R) . offset.
      const ar0 = a0 * R[0] + a2 * R[6], ar1 = a0 * R[1] + a2 * R[7], ar2 = a0 * R[2] + a2 * R[8];
      const br0 = b1 * R[3] + b2 * R[6], br1 = b1 * R[4] + b2 * R[7], br2 = b1 * R[5] + b2 * R[8];
      if (!poseOnly) {
        for (let k = 0, d = i * K * 3; k < K; k++, d += 3) {
          J[6 + k] = ar0 * D[d] + ar1 * D[d + 1] + ar2 * D[d + 2];
          J[n + 6 + k] = br0 * D[d] + br1 * D[d + 1] + br2 * D[d + 2];
        }
      }
      const c = b.weight[i] / b.weightSum;
      if (!poseOnly && !o.exactHessian) {
        const ar = [ar0, ar1, ar2], br = [br0, br1, br2];
        kPairs.forEach(([u, v], p) => (M[p] += c * (ar[u] * ar[v] + br[u] * br[v])));
      }
      const rows = poseOnly || o.exactHessian ? n : kPoseUnknowns;
      for (let r = 0; r < n; r++) {
        const ju = c * J[r], jv = c * J[n + r];
        g[r] += ju * ru + jv * rv;
        if (r >= rows) continue;
        const row = r * n;
        for (let q = r; q < n; q++) H[row + q] += ju * J[q] + jv * J[n + q];
      }
    }
    if (!poseOnly && !o.exactHessian) addWeightBlock(b, M, H, n);
    addPriors(s, prior, o, H, g, n);
  }

  // The weights' block of H from the points' mean of (a R)^T (a R) + (b R)^T
  // (b R) (M, 6 pairs) and the basis' offset products: exact for an affine
  // camera, close for a face far from the camera against its depth; the
  // gradient stays exact, so the solution does not change, only the steps.
  function addWeightBlock(b, M, H, n) {
    const K = b.K, G = b.offsetProducts;
    for (let k = 0; k < K; k++) {
      const row = (kPoseUnknowns + k) * n + kPoseUnknowns;
      for (let l = k; l < K; l++) {
        let h = 0;
        for (let p = 0; p < 6; p++) h += M[p] * G[(p * K + k) * K + l];
        H[row + l] += h;
      }
    }
  }

  // The priors' Gauss-Newton terms (halved costs: H = J^T J, g = J^T r).
  function addPriors(s, prior, o, H, g, n) {
    for (let k = 0; k + kPoseUnknowns < n; k++) {
      const j = kPoseUnknowns + k;
      H[j * n + j] += o.pull.lambda[k];
      g[j] += o.pull.lambda[k] * (s.w[k] - o.pull.mean[k]);
      if (prior) {
        H[j * n + j] += o.temporalWeights;
        g[j] += o.temporalWeights * (s.w[k] - prior.w[k]);
      }
    }
    if (!prior) return;
    const phi = logRotation(mul3(s.R, transpose3(prior.R)));
    for (let c = 0; c < 3; c++) {
      H[c * n + c] += o.temporalRotation;
      g[c] += o.temporalRotation * phi[c];
      H[(3 + c) * n + 3 + c] += o.temporalTranslation;
      g[3 + c] += o.temporalTranslation * (s.t[c] - prior.t[c]);
    }
  }

  // Solves (H + mu diag(H)) x = -g over the unknowns in `free` (H's upper
  // triangle) by Cholesky; the others stay 0. False when not positive definite.
  function dampedStep(H, g, n, free, mu, x) {
    const m = free.length, L = new Float64Array(m * m);
    for (let a = 0; a < m; a++)
      for (let c = a; c < m; c++) L[c * m + a] = H[free[a] * n + free[c]];
    for (let a = 0; a < m; a++) L[a * m + a] *= 1 + mu;
    for (let j = 0; j < m; j++) {
      let d = L[j * m + j];
      for (let k = 0; k < j; k++) d -= L[j * m + k] * L[j * m + k];
      if (!(d > 0)) return false;
      const ljj = Math.sqrt(d);
      L[j * m + j] = ljj;
      for (let i = j + 1; i < m; i++) {
        let v = L[i * m + j];
        for (let k = 0; k < j; k++) v -= L[i * m + k] * L[j * m + k];
        L[i * m + j] = v / ljj;
      }
    }
    const y = new Float64Array(m);
    for (let i = 0; i < m; i++) {
      let v = -g[free[i]];
      for (let k = 0; k < i; k++) v -= L[i * m + k] * y[k];
      y[i] = v / L[i * m + i];
    }
    for (let i = m - 1; i >= 0; i--) {
      let v = y[i];
      for (let k = i + 1; k < m; k++) v -= L[k * m + i] * y[k];
      y[i] = v / L[i * m + i];
    }
    x.fill(0);
    for (let i = 0; i < m; i++) x[free[i]] = y[i];
    return true;
  }

  // Damped Gauss-Newton (Levenberg-Marquardt) from state s, in place. The
  // weights are projected onto [0, 1]; those at a bound whose gradient points
  // out are held for the step. Returns the number of linear solves.
  function levenbergMarquardt(s, b, pts, cam, prior, o, X, maxIterations, poseOnly) {
    const n = poseOnly ? kPoseUnknowns : kPoseUnknowns + b.K;
    const H = new Float64Array(n * n), g = new Float64Array(n), step = new Float64Array(n);
    let e = cost(s, b, pts, cam, prior, o, X), mu = o.damping, it = 0;
    while (it < maxIterations) {
      normalEquations(s, b, pts, cam, prior, o, X, H, g, poseOnly);
      const free = [];
      for (let j = 0; j < n; j++) {
        const w = j < kPoseUnknowns ? 0.5 : s.w[j - kPoseUnknowns];
        if ((w <= 0 && g[j] > 0) || (w >= 1 && g[j] < 0)) continue;
        free.push(j);
      }
      let decrease = -1;
      while (it < maxIterations && decrease < 0) {
        it++;
        if (!dampedStep(H, g, n, free, mu, step)) {
          mu = Math.max(mu * 10, 1e-6);
          continue;
        }
        const trial = applyStep(s, step, poseOnly);
        const et = cost(trial, b, pts, cam, prior, o, X);
        if (et < e) {
          decrease = e - et;
          Object.assign(s, trial);
          e = et;
          mu = Math.max(mu / 3, 1e-9);
        } else {
          mu = Math.max(mu * 4, 1e-6);
        }
      }
      if (decrease < o.tolerance * Math.max(e, 1)) break;
    }
    s.cost = e;
    return it;
  }

  function applyStep(s, step, poseOnly) {
    const R = mul3(rodrigues([step[0], step[1], step[2]]), s.R);
    const t = [s.t[0] + step[3], s.t[1] + step[4], s.t[2] + step[5]];
    const w = Float64Array.from(s.w);
    if (!poseOnly)
      for (let k = 0; k < w.length; k++) w[k] = Math.min(1, Math.max(0, w[k] + step[kPoseUnknowns + k]));
    return { R, t, w };
  }

  // A first pose with no previous frame: the affine camera that best maps the
  // neutral points to the image points (weighted least squares), its rows
  // made a rotation, the depth from its scale. Weights 0.
  function initialPose(b, pts, cam) {
    let sw = 0;
    const nm = [0, 0, 0], pm = [0, 0];
    for (let i = 0; i < kPoints; i++) {
      const c = b.weight[i];
      sw += c;
      for (let d = 0; d < 3; d++) nm[d] += c * b.neutral[3 * i + d];
      pm[0] += c * pts[3 * i];
      pm[1] += c * pts[3 * i + 1];
    }
    for (let d = 0; d < 3; d++) nm[d] /= sw;
    pm[0] /= sw;
    pm[1] /= sw;
    const A = new Float64Array(9), bu = [0, 0, 0], bv = [0, 0, 0];
    for (let i = 0; i < kPoints; i++) {
      const c = b.weight[i];
      const q = [0, 1, 2].map((d) => b.neutral[3 * i + d] - nm[d]);
      const u = pts[3 * i] - pm[0], v = pts[3 * i + 1] - pm[1];
      for (let r = 0; r < 3; r++) {
        for (let k = 0; k < 3; k++) A[3 * r + k] += c * q[r] * q[k];
        bu[r] += c * q[r] * u;
        bv[r] += c * q[r] * v;
      }
    }
    const Ai = inverse3(A), m1 = mulVec3(Ai, bu), m2 = mulVec3(Ai, bv);
    const n1 = Math.hypot(...m1), r1 = m1.map((x) => x / n1);
    const along = dot3(m2, r1), r2raw = m2.map((x, d) => x - along * r1[d]);
    const n2 = Math.hypot(...r2raw), r2 = r2raw.map((x) => x / n2);
    const R = [...r1, ...r2, ...cross3(r1, r2)];
    const z = (cam.fx / n1 + cam.fy / Math.hypot(...m2)) / 2;
    const rn = mulVec3(R, nm);
    const t = [(pm[0] - cam.cx) * z / cam.fx - rn[0], (pm[1] - cam.cy) * z / cam.fy - rn[1], z - rn[2]];
    return { R, t, w: new Float64Array(b.K) };
  }

  // The pull on each expression weight: with options.expressionPrior
  // ({mean: [K], spread: [K]}, the avatar's training frames' tracked weights)
  // a Gaussian prior, toward the mean and as strong as the spread is narrow,
  // scaled as if each point's coordinates had priorNoise px of independent
  // noise (the data term is a mean over the points, so the prior is divided
  // by their weight); without it, the ridge toward 0. Weights the avatar
  // never showed are then held near what it did show.
  function weightPull(o, b) {
    const K = b.K, p = o.expressionPrior;
    if (!p) return { mean: new Float64Array(K), lambda: new Float64Array(K).fill(o.ridge) };
    if (p.mean.length !== K || p.spread.length !== K)
      throw new Error(`expressionPrior has ${p.mean.length} means and ${p.spread.length} spreads for ${K} weights`);
    const scale = o.priorNoise * o.priorNoise / b.weightSum;
    return {
      mean: Float64Array.from(p.mean),
      lambda: Float64Array.from(p.spread, (d) => o.ridge + scale / Math.max(d, o.priorMinSpread) ** 2),
    };
  }

  const kSolveDefaults = {
    ovalWeight: 0.3,             // the face oval's points, against 1 for the others
    ridge: 0.02,                 // px^2 per weight^2: pulls unseen weights to 0
    expressionPrior: null,       // {mean, spread}: see weightPull
    priorNoise: 1,               // px: a point's noise for expressionPrior's strength
    priorMinSpread: 0.02,        // a weight's spread at the least (its pull at the most)
    temporalWeights: 0.05,       // px^2 per (weight - previous)^2
    temporalRotation: 100,       // px^2 per rad^2 of turn from the previous pose
    temporalTranslation: 1000,   // px^2 per m^2 of shift from the previous pose
    damping: 1e-3,               // Levenberg-Marquardt's first mu (relative to diag(H))
    exactHessian: false,         // the weights' block of H point by point (slower; see addWeightBlock)
    tolerance: 1e-3,             // stop when a step lowers the cost by less than this fraction
    poseOnly: false,             // hold the weights (0, or `previous`'s) and fit the pose alone
    iterations: 6,               // linear solves when warm-started from `previous`
    firstPoseIterations: 20,     // without `previous`: pose alone from the affine guess,
    firstIterations: 30,         // then pose and weights
  };

  // Head pose (camera frame: X_c = R X + t, OpenCV axes) and expression
  // weights whose projected basis points best match `points` (468 x (x, y,
  // ...) image pixels). The cost is the weighted mean of squared pixel
  // residuals (the face oval's points weighted less) plus a ridge on the
  // weights and, with `previous` (a result of this function), a pull toward
  // it; every prior is in px^2 (options: kSolveDefaults). camera: {fx, fy,
  // cx, cy} of the image. Returns {weights: Float64Array(K), rotation: 9
  // numbers row-major, translation: [3] (metres), residual_px (median
  // distance), iterations (linear solves), cost}.
  function solveFace(points, basis, camera, previous, options = {}) {
    const o = Object.assign({}, kSolveDefaults, options);
    const b = packBasis(basis, o.ovalWeight);
    o.pull = weightPull(o, b);
    const X = new Float64Array(kPoints * 3);
    let prior = null, s, iterations = 0;
    if (previous) {
      prior = { R: flatRotation(previous.rotation), t: Array.from(previous.translation), w: Float64Array.from(previous.weights) };
      s = { R: prior.R.slice(), t: prior.t.slice(), w: Float64Array.from(prior.w) };
    } else {
      s = initialPose(b, points, camera);
      iterations += levenbergMarquardt(s, b, points, camera, null, o, X, o.firstPoseIterations, true);
    }
    if (!o.poseOnly)
      iterations += levenbergMarquardt(s, b, points, camera, prior, o, X, prior ? o.iterations : o.firstIterations, false);
    else if (prior)
      iterations += levenbergMarquardt(s, b, points, camera, prior, o, X, o.iterations, true);
    return {
      weights: s.w,
      rotation: s.R,
      translation: s.t,
      residual_px: medianResidual(s, b, points, camera, X),
      iterations,
      cost: s.cost,
    };
  }

  // A copy of `basis` whose neutral is moved, point by point, so that with
  // each fit's pose and weights (solveFace results for the point sets) it
  // projects onto the points (on average over the sets): the face of
  // whoever drives, and the detector's own placement of its points, in place
  // of the captured subject's. Each point moves parallel to the image plane
  // at its own depth. Call it on a few frames (a second or so) where the
  // driver holds a neutral face, fitted with {poseOnly: true}. pointSets and
  // fits: arrays, or one point set and one fit.
  function calibrateNeutral(pointSets, basis, camera, fits) {
    if (!Array.isArray(fits)) [pointSets, fits] = [[pointSets], [fits]];
    const b = packBasis(basis, kSolveDefaults.ovalWeight), X = new Float64Array(kPoints * 3);
    const moves = new Float64Array(kPoints * 3);
    fits.forEach((fit, f) => {
      const points = pointSets[f], R = flatRotation(fit.rotation), Rt = transpose3(R), t = fit.translation;
      modelPoints(b, fit.weights, X);
      for (let i = 0; i < kPoints; i++) {
        const Y = mulVec3(R, [X[3 * i], X[3 * i + 1], X[3 * i + 2]]).map((y, c) => y + t[c]);
        const seen = [(points[3 * i] - camera.cx) / camera.fx * Y[2], (points[3 * i + 1] - camera.cy) / camera.fy * Y[2]];
        const move = mulVec3(Rt, [seen[0] - Y[0], seen[1] - Y[1], 0]);
        for (let c = 0; c < 3; c++) moves[3 * i + c] += move[c] / fits.length;
      }
    });
    const neutral = basis.neutral.map((p, i) => p.map((x, c) => x + moves[3 * i + c]));
    return Object.assign({}, basis, { neutral });
  }

  function medianResidual(s, b, pts, cam, X) {
    modelPoints(b, s.w, X);
    const d = new Float64Array(kPoints), R = s.R, t = s.t;
    for (let i = 0; i < kPoints; i++) {
      const x = X[3 * i], y = X[3 * i + 1], z = X[3 * i + 2];
      const cz = R[6] * x + R[7] * y + R[8] * z + t[2];
      const u = cam.fx * (R[0] * x + R[1] * y + R[2] * z + t[0]) / cz + cam.cx;
      const v = cam.fy * (R[3] * x + R[4] * y + R[5] * z + t[1]) / cz + cam.cy;
      d[i] = Math.hypot(u - pts[3 * i], v - pts[3 * i + 1]);
    }
    d.sort();
    return (d[(kPoints - 1) >> 1] + d[kPoints >> 1]) / 2;
  }

  // ------------------------------------------------------------ 3x3 algebra
  // Matrices are 9 numbers, row-major.

  function flatRotation(R) {
    return Array.isArray(R[0]) ? [...R[0], ...R[1], ...R[2]] : Array.from(R);
  }
  function mul3(A, B) {
    const C = new Array(9);
    for (let r = 0; r < 3; r++)
      for (let c = 0; c < 3; c++) C[3 * r + c] = A[3 * r] * B[c] + A[3 * r + 1] * B[3 + c] + A[3 * r + 2] * B[6 + c];
    return C;
  }
  function mulVec3(A, v) {
    return [0, 1, 2].map((r) => A[3 * r] * v[0] + A[3 * r + 1] * v[1] + A[3 * r + 2] * v[2]);
  }
  function transpose3(A) {
    return [A[0], A[3], A[6], A[1], A[4], A[7], A[2], A[5], A[8]];
  }
  function dot3(a, b) {
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
  }
  function cross3(a, b) {
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
  }
  function inverse3(A) {
    const c0 = cross3(A.slice(3, 6), A.slice(6, 9)), c1 = cross3(A.slice(6, 9), A.slice(0, 3));
    const c2 = cross3(A.slice(0, 3), A.slice(3, 6)), det = dot3(A.slice(0, 3), c0);
    return [c0[0], c1[0], c2[0], c0[1], c1[1], c2[1], c0[2], c1[2], c2[2]].map((x) => x / det);
  }
  // Axis-angle -> rotation.
  function rodrigues(w) {
    const th = Math.hypot(w[0], w[1], w[2]);
    const a = th < 1e-8 ? 1 : Math.sin(th) / th, b = th < 1e-8 ? 0.5 : (1 - Math.cos(th)) / (th * th);
    const [x, y, z] = w;
    return [1 - b * (y * y + z * z), -a * z + b * x * y, a * y + b * x * z,
            a * z + b * x * y, 1 - b * (x * x + z * z), -a * x + b * y * z,
            -a * y + b * x * z, a * x + b * y * z, 1 - b * (x * x + y * y)];
  }
  // Rotation -> axis-angle (angles below pi).
  function logRotation(R) {
    const c = Math.min(1, Math.max(-1, (R[0] + R[4] + R[8] - 1) / 2)), th = Math.acos(c);
    const k = th < 1e-8 ? 0.5 : th / (2 * Math.sin(th));
    return [k * (R[7] - R[5]), k * (R[2] - R[6]), k * (R[3] - R[1])];
  }
  // The angle of a rotation, degrees.
  function rotationAngleDeg(R) {
    return Math.acos(Math.min(1, Math.max(-1, (R[0] + R[4] + R[8] - 1) / 2))) * 180 / Math.PI;
  }

  function now() {
    return typeof performance !== 'undefined' ? performance.now() : Date.now();
  }

  return {
    FaceMeshTracker, loadFaceMesh, solveFace, calibrateNeutral, regionToImage, regionFromMesh, searchRegions, cropInto,
    rodrigues, logRotation, rotationAngleDeg, mul3, transpose3, kFaceOval, kSolveDefaults,
    internal: { packBasis, cost, normalEquations, applyStep },
  };
})();

if (typeof module !== 'undefined') module.exports = HeadforgeFaceDrive;
