#include "export/viewer.h"

#include "export/html_util.h"

namespace headforge {
namespace {

// The page's own script: the avatars from base64 blocks into blob URLs,
// loaded as glTF containers; the mesh's animation looped; an orbit camera.
const char* const kViewerScript = R"JS(
(function () {
  const canvas = document.getElementById('view');
  const app = new pc.Application(canvas, {
    mouse: new pc.Mouse(canvas),
    graphicsDeviceOptions: { antialias: true, preserveDrawingBuffer: true },
  });
  app.setCanvasFillMode(pc.FILLMODE_FILL_WINDOW);
  app.setCanvasResolution(pc.RESOLUTION_AUTO);
  window.addEventListener('resize', () => app.resizeCanvas());
  app.start();

  const camera = new pc.Entity('camera');
  camera.addComponent('camera', { clearColor: new pc.Color(0.16, 0.17, 0.19), nearClip: 0.01, farClip: 50, fov: 30 });
  app.root.addChild(camera);
  // Orbit round the point between the two heads: drag turns, the wheel zooms.
  const orbit = { yaw: 0, pitch: 0, distance: 0.9, target: new pc.Vec3(0, 0.0, 0) };
  const place = () => {
    const q = new pc.Quat().setFromEulerAngles(orbit.pitch, orbit.yaw, 0);
    const back = q.transformVector(new pc.Vec3(0, 0, orbit.distance));
    camera.setPosition(orbit.target.x + back.x, orbit.target.y + back.y, orbit.target.z + back.z);
    camera.setRotation(q);
  };
  place();
  let dragging = false;
  app.mouse.on(pc.EVENT_MOUSEDOWN, () => { dragging = true; });
  app.mouse.on(pc.EVENT_MOUSEUP, () => { dragging = false; });
  app.mouse.on(pc.EVENT_MOUSEMOVE, (e) => {
    if (!dragging) return;
    orbit.yaw -= e.dx * 0.3;
    orbit.pitch = Math.max(-80, Math.min(80, orbit.pitch - e.dy * 0.3));
    place();
  });
  app.mouse.on(pc.EVENT_MOUSEWHEEL, (e) => {
    orbit.distance = Math.max(0.2, Math.min(5, orbit.distance * (e.wheelDelta > 0 ? 1.1 : 0.9)));
    place();
  });

  const blobUrl = (id) => {
    const text = document.getElementById(id).textContent.trim();
    const bytes = Uint8Array.from(atob(text), (c) => c.charCodeAt(0));
    return URL.createObjectURL(new Blob([bytes], { type: 'model/gltf-binary' }));
  };
  const load = (id, x, done) => {
    if (!document.getElementById(id)) { done(null); return; }
    const asset = new pc.Asset(id, 'container', { url: blobUrl(id), filename: id + '.glb' });
    asset.on('load', () => {
      const entity = asset.resource.instantiateRenderEntity();
      const holder = new pc.Entity(id);
      holder.setPosition(x, 0, 0);
      holder.addChild(entity);
      app.root.addChild(holder);
      done(asset, entity);
    });
    asset.on('error', (e) => { window.failed = id + ': ' + e; });
    app.assets.add(asset);
    app.assets.load(asset);
  };
  let pending = 2;
  const ready = () => {
    if (--pending > 0) return;
    let frames = 0;
    app.on('frameend', () => { if (++frames === 30) window.done = true; });
  };
  const both = document.getElementById('mesh') && document.getElementById('gaussians');
  load('mesh', both ? -0.13 : 0, (asset, entity) => {
    if (asset && asset.resource.animations.length) {
      // Loop the tracked sequence on the head node.
      entity.addComponent('anim', { activate: true });
      entity.anim.assignAnimation('tracked', asset.resource.animations[0].resource);
    }
    ready();
  });
  load('gaussians', both ? 0.13 : 0, () => ready());
})();
)JS";

}  // namespace

Status WriteViewer(const fs::path& out_dir, const ViewerOptions& options) {
  std::string engine;
  if (options.playcanvas_js.empty() || !ReadFileToString(options.playcanvas_js, &engine).ok())
    return Status::NotFound("export: the viewer needs PlayCanvas's playcanvas.min.js (" + options.playcanvas_js +
                            "); scripts/install_deps.sh installs it from npm, or leave viewer out of --formats");
  std::string html = R"(<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>HeadForge avatar</title>
<meta name="viewport" content="width=device-width, initial-scale=1">
<style>
html, body { margin: 0; height: 100%; overflow: hidden; background: #292b30; font: 13px system-ui, sans-serif; }
canvas { width: 100%; height: 100%; display: block; }
#legend { position: absolute; left: 12px; top: 10px; color: #ddd; }
</style>
)";
  html += "<script>" + InlineScriptText(engine) + "</script>\n</head><body>\n<canvas id=\"view\"></canvas>\n";
  std::string legend;
  for (const auto& [id, path, what] :
       {std::tuple<const char*, fs::path, const char*>{"mesh", options.mesh_glb, "the mesh avatar, playing the tracked sequence"},
        std::tuple<const char*, fs::path, const char*>{"gaussians", options.gaussians_glb, "the Gaussian avatar"}}) {
    std::string bytes;
    if (path.empty() || !ReadFileToString(path, &bytes).ok()) continue;
    html += std::string("<script id=\"") + id + "\" type=\"application/octet-stream\">" + Base64(bytes) + "</script>\n";
    legend += std::string(legend.empty() ? "" : "; ") + what;
  }
  if (legend.empty()) return Status::NotFound("export: the viewer has no avatar to show (no mesh or Gaussian GLB)");
  const bool both = legend.find(';') != std::string::npos;
  html += "<div id=\"legend\">" +
          HtmlEscape(both ? "Left: " + legend.substr(0, legend.find(';')) + ". Right:" + legend.substr(legend.find(';') + 1) + "."
                          : legend + ".") +
          " Drag to turn, wheel to zoom.</div>\n";
  html += std::string("<script>") + kViewerScript + "</script>\n</body></html>\n";
  HF_RETURN_IF_ERROR(EnsureDirectory(out_dir));
  return WriteFileAtomic(out_dir / "index.html", html);
}

}  // namespace headforge
