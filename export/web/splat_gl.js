// A WebGL 2 Gaussian splat renderer for pages that pose their Gaussians
// every frame (the drive page): the same projection and blending as the
// CPU rasterizer (avatar/splat): a pinhole camera with pixel centres at
// integers, the 2D covariance widened by 0.3 px² on its diagonal, alpha =
// min(opacity * exp(-sigma), 0.999) and nothing under 1/255, composited
// front to back over a plain background. The Gaussians are sorted by depth
// on the CPU each frame and drawn back to front as instanced quads into a
// half-float target (where the device has one), so the blending keeps more
// than 8 bits, then copied to the canvas.
const HeadforgeSplatGL = (() => {
  const kVertex = `#version 300 es
precision highp float;
layout(location = 0) in vec2 corner;     // the quad's corner in [-1, 1]^2
layout(location = 1) in vec3 mean;       // camera frame
layout(location = 2) in vec3 covA;       // camera-frame 3D covariance: xx, xy, xz
layout(location = 3) in vec3 covB;       // yy, yz, zz
layout(location = 4) in vec4 colour;     // rgb, opacity
uniform vec4 lens;                       // fx, fy, cx, cy
uniform vec2 size;                       // width, height
out vec2 offset;                         // pixels from the centre
out vec3 conic;
out vec4 tint;
void main() {
  float z = mean.z;
  if (z < 0.01) { gl_Position = vec4(0, 0, 2, 1); return; }
  mat3 cov = mat3(covA.x, covA.y, covA.z, covA.y, covB.x, covB.y, covA.z, covB.y, covB.z);
  // The projection's Jacobian at the view direction clamped to the image
  // widened by 0.3 of its size on each side (the rasterizer's clip margin).
  float mx = 0.3 * size.x / lens.x, my = 0.3 * size.y / lens.y;
  float tx = z * clamp(mean.x / z, -(lens.z + 0.5) / lens.x - mx, (size.x - 0.5 - lens.z) / lens.x + mx);
  float ty = z * clamp(mean.y / z, -(lens.w + 0.5) / lens.y - my, (size.y - 0.5 - lens.w) / lens.y + my);
  mat3x2 j = mat3x2(lens.x / z, 0.0, 0.0, lens.y / z, -lens.x * tx / (z * z), -lens.y * ty / (z * z));
  mat2 c2 = j * cov * transpose(j);
  c2[0][0] += 0.3;
  c2[1][1] += 0.3;
  float det = c2[0][0] * c2[1][1] - c2[0][1] * c2[1][0];
  if (!(det > 0.0)) { gl_Position = vec4(0, 0, 2, 1); return; }
  conic = vec3(c2[1][1], -c2[0][1], c2[0][0]) / det;
  float mid = 0.5 * (c2[0][0] + c2[1][1]);
  float radius = ceil(3.0 * sqrt(mid + sqrt(max(0.1, mid * mid - det))));
  vec2 centre = vec2(lens.x * mean.x / z + lens.z, lens.y * mean.y / z + lens.w);
  offset = corner * radius;
  vec2 pixel = centre + offset;
  gl_Position = vec4((pixel.x + 0.5) / size.x * 2.0 - 1.0, 1.0 - (pixel.y + 0.5) / size.y * 2.0, 0.0, 1.0);
  tint = colour;
}`;
  const kFragment = `#version 300 es
precision highp float;
in vec2 offset;
in vec3 conic;
in vec4 tint;
out vec4 result;
void main() {
  // offset runs from the centre to the pixel; the rasterizer's d runs the other way.
  vec2 d = -offset;
  float sigma = 0.5 * (conic.x * d.x * d.x + conic.z * d.y * d.y) + conic.y * d.x * d.y;
  float alpha = min(tint.a * exp(-sigma), 0.999);
  if (sigma < 0.0 || alpha < 1.0 / 255.0) discard;
  result = vec4(tint.rgb * alpha, alpha);
}`;
  const kCopyVertex = `#version 300 es
layout(location = 0) in vec2 corner;
out vec2 uv;
void main() { uv = corner * 0.5 + 0.5; gl_Position = vec4(corner, 0, 1); }`;
  const kCopyFragment = `#version 300 es
precision highp float;
uniform sampler2D image;
in vec2 uv;
out vec4 result;
void main() { result = vec4(texture(image, uv).rgb, 1.0); }`;

  function compile(gl, vertex, fragment) {
    const program = gl.createProgram();
    for (const [type, text] of [[gl.VERTEX_SHADER, vertex], [gl.FRAGMENT_SHADER, fragment]]) {
      const shader = gl.createShader(type);
      gl.shaderSource(shader, text);
      gl.compileShader(shader);
      if (!gl.getShaderParameter(shader, gl.COMPILE_STATUS)) throw new Error('splat shader: ' + gl.getShaderInfoLog(shader));
      gl.attachShader(program, shader);
    }
    gl.linkProgram(program);
    if (!gl.getProgramParameter(program, gl.LINK_STATUS)) throw new Error('splat program: ' + gl.getProgramInfoLog(program));
    return program;
  }

  // The per-Gaussian data the shader takes, in camera space, depth-sorted
  // back to front: 3 + 6 + 4 floats each. `g` holds the posed Gaussians in
  // the head frame as the blendshapes lay them out, 13 floats each
  // (position 3, rotation w x y z, log-scale 3, RGB), and `opacities` [N];
  // camFromHead is the row-major 3 x 4 [R | t].
  function cameraSpace(g, opacities, camFromHead, out, order, depth) {
    const n = opacities.length, m = camFromHead;
    for (let i = 0; i < n; ++i) {
      const x = g[13 * i], y = g[13 * i + 1], z = g[13 * i + 2];
      depth[i] = m[8] * x + m[9] * y + m[10] * z + m[11];
    }
    for (let i = 0; i < n; ++i) order[i] = i;
    order.sort((a, b) => depth[b] - depth[a]);
    for (let k = 0; k < n; ++k) {
      const i = order[k], o = 13 * k, p = 13 * i;
      const x = g[p], y = g[p + 1], z = g[p + 2];
      out[o] = m[0] * x + m[1] * y + m[2] * z + m[3];
      out[o + 1] = m[4] * x + m[5] * y + m[6] * z + m[7];
      out[o + 2] = depth[i];
      let qw = g[p + 3], qx = g[p + 4], qy = g[p + 5], qz = g[p + 6];
      const len = Math.hypot(qw, qx, qy, qz) || 1;
      qw /= len; qx /= len; qy /= len; qz /= len;
      // M = (camera rotation) R(q) S; cov = M M^T.
      const r = [1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy - qw * qz), 2 * (qx * qz + qw * qy),
                 2 * (qx * qy + qw * qz), 1 - 2 * (qx * qx + qz * qz), 2 * (qy * qz - qw * qx),
                 2 * (qx * qz - qw * qy), 2 * (qy * qz + qw * qx), 1 - 2 * (qx * qx + qy * qy)];
      const s0 = Math.exp(g[p + 7]), s1 = Math.exp(g[p + 8]), s2 = Math.exp(g[p + 9]);
      const a = new Array(9);
      for (let row = 0; row < 3; ++row)
        for (let col = 0; col < 3; ++col) {
          const s = col === 0 ? s0 : col === 1 ? s1 : s2;
          a[3 * row + col] = (m[4 * row] * r[col] + m[4 * row + 1] * r[3 + col] + m[4 * row + 2] * r[6 + col]) * s;
        }
      const dot = (p, q) => a[3 * p] * a[3 * q] + a[3 * p + 1] * a[3 * q + 1] + a[3 * p + 2] * a[3 * q + 2];
      out[o + 3] = dot(0, 0); out[o + 4] = dot(0, 1); out[o + 5] = dot(0, 2);
      out[o + 6] = dot(1, 1); out[o + 7] = dot(1, 2); out[o + 8] = dot(2, 2);
      out[o + 9] = Math.min(Math.max(g[p + 10], 0), 1);
      out[o + 10] = Math.min(Math.max(g[p + 11], 0), 1);
      out[o + 11] = Math.min(Math.max(g[p + 12], 0), 1);
      out[o + 12] = opacities[i];
    }
  }

  // A renderer drawing into `canvas` at width x height pixels over the grey
  // `background` (0-1).
  function create(canvas, width, height, background) {
    canvas.width = width;
    canvas.height = height;
    const gl = canvas.getContext('webgl2', { antialias: false, premultipliedAlpha: false, preserveDrawingBuffer: true });
    if (!gl) throw new Error('this browser has no WebGL 2');
    const splat = compile(gl, kVertex, kFragment), copy = compile(gl, kCopyVertex, kCopyFragment);
    const quad = gl.createBuffer();
    gl.bindBuffer(gl.ARRAY_BUFFER, quad);
    gl.bufferData(gl.ARRAY_BUFFER, new Float32Array([-1, -1, 1, -1, -1, 1, 1, 1]), gl.STATIC_DRAW);
    const instances = gl.createBuffer();
    const vao = gl.createVertexArray();
    gl.bindVertexArray(vao);
    gl.bindBuffer(gl.ARRAY_BUFFER, quad);
    gl.enableVertexAttribArray(0);
    gl.vertexAttribPointer(0, 2, gl.FLOAT, false, 0, 0);
    gl.bindBuffer(gl.ARRAY_BUFFER, instances);
    const fields = [[1, 3, 0], [2, 3, 3], [3, 3, 6], [4, 4, 9]];
    for (const [location, count, first] of fields) {
      gl.enableVertexAttribArray(location);
      gl.vertexAttribPointer(location, count, gl.FLOAT, false, 13 * 4, first * 4);
      gl.vertexAttribDivisor(location, 1);
    }
    const copyVao = gl.createVertexArray();
    gl.bindVertexArray(copyVao);
    gl.bindBuffer(gl.ARRAY_BUFFER, quad);
    gl.enableVertexAttribArray(0);
    gl.vertexAttribPointer(0, 2, gl.FLOAT, false, 0, 0);
    gl.bindVertexArray(null);
    // A half-float target where the device renders to one; else the canvas.
    let target = null, texture = null;
    if (gl.getExtension('EXT_color_buffer_float') || gl.getExtension('EXT_color_buffer_half_float')) {
      texture = gl.createTexture();
      gl.bindTexture(gl.TEXTURE_2D, texture);
      gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGBA16F, width, height, 0, gl.RGBA, gl.HALF_FLOAT, null);
      gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MIN_FILTER, gl.NEAREST);
      gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MAG_FILTER, gl.NEAREST);
      target = gl.createFramebuffer();
      gl.bindFramebuffer(gl.FRAMEBUFFER, target);
      gl.framebufferTexture2D(gl.FRAMEBUFFER, gl.COLOR_ATTACHMENT0, gl.TEXTURE_2D, texture, 0);
      if (gl.checkFramebufferStatus(gl.FRAMEBUFFER) !== gl.FRAMEBUFFER_COMPLETE) target = null;
      gl.bindFramebuffer(gl.FRAMEBUFFER, null);
    }
    let data = new Float32Array(0), order = new Uint32Array(0), depth = new Float32Array(0);
    return {
      halfFloat: target !== null,
      // Draws `g` and `opacities` (see cameraSpace) through the camera:
      // lens {fx, fy, cx, cy}.
      draw(g, opacities, camFromHead, lens) {
        const n = opacities.length;
        if (data.length !== 13 * n) {
          data = new Float32Array(13 * n);
          order = new Array(n);
          depth = new Float32Array(n);
        }
        const start = performance.now();
        cameraSpace(g, opacities, camFromHead, data, order, depth);
        const sorted = performance.now();
        gl.bindFramebuffer(gl.FRAMEBUFFER, target);
        gl.viewport(0, 0, width, height);
        gl.clearColor(background, background, background, 1);
        gl.clear(gl.COLOR_BUFFER_BIT);
        gl.enable(gl.BLEND);
        gl.blendFunc(gl.ONE, gl.ONE_MINUS_SRC_ALPHA);
        gl.useProgram(splat);
        gl.uniform4f(gl.getUniformLocation(splat, 'lens'), lens.fx, lens.fy, lens.cx, lens.cy);
        gl.uniform2f(gl.getUniformLocation(splat, 'size'), width, height);
        gl.bindBuffer(gl.ARRAY_BUFFER, instances);
        gl.bufferData(gl.ARRAY_BUFFER, data, gl.DYNAMIC_DRAW);
        gl.bindVertexArray(vao);
        gl.drawArraysInstanced(gl.TRIANGLE_STRIP, 0, 4, n);
        gl.disable(gl.BLEND);
        if (target) {
          gl.bindFramebuffer(gl.FRAMEBUFFER, null);
          gl.useProgram(copy);
          gl.activeTexture(gl.TEXTURE0);
          gl.bindTexture(gl.TEXTURE_2D, texture);
          gl.uniform1i(gl.getUniformLocation(copy, 'image'), 0);
          gl.bindVertexArray(copyVao);
          gl.drawArrays(gl.TRIANGLE_STRIP, 0, 4);
        }
        gl.bindVertexArray(null);
        // Waits for the device: the times are the frame's, and frames do not queue.
        gl.finish();
        return { ms_sort: sorted - start, ms_gl: performance.now() - sorted };
      },
    };
  }

  return { create, cameraSpace };
})();
if (typeof module !== 'undefined') module.exports = HeadforgeSplatGL;
