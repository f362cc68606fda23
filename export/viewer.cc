#include "export/viewer.h"

#include <cctype>
#include <cstdio>
#include <vector>

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
  // Orbit round the point between the two heads: drag turns, the wheel zooms;
  // ?yaw=DEG opens the page turned (180: from behind, for a 360-degree capture).
  const startYaw = Number(new URLSearchParams(location.search).get('yaw')) || 0;
  const orbit = { yaw: startYaw, pitch: 0, distance: 0.9, target: new pc.Vec3(0, 0.0, 0) };
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

  const blobUrl = (id, type) => {
    const text = document.getElementById(id).textContent.trim();
    const bytes = Uint8Array.from(atob(text), (c) => c.charCodeAt(0));
    return URL.createObjectURL(new Blob([bytes], { type }));
  };
  const load = (id, x, done) => {
    if (!document.getElementById(id)) { done(null); return; }
    const asset = new pc.Asset(id, 'container', { url: blobUrl(id, 'model/gltf-binary'), filename: id + '.glb' });
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
  // The baked clip: one splat entity a frame, the one whose time has come
  // shown (or the K-th held with ?clip=K).
  const clipBlocks = Array.from(document.querySelectorAll('script[data-clip-time]'));
  const clip = { entities: [], times: clipBlocks.map((b) => Number(b.dataset.clipTime)), shown: -1 };
  const hold = new URLSearchParams(location.search).get('clip');
  const showClip = (index) => {
    if (index === clip.shown) return;
    clip.entities.forEach((e, i) => { e.enabled = i === index; });
    clip.shown = index;
    window.clipShown = index;
  };
  const loadClip = (x, done) => {
    if (!clipBlocks.length) { done(); return; }
    const holder = new pc.Entity('clip');
    holder.setPosition(x, 0, 0);
    app.root.addChild(holder);
    let left = clipBlocks.length;
    clipBlocks.forEach((block, i) => {
      const asset = new pc.Asset(block.id, 'gsplat',
                                 { url: blobUrl(block.id, 'application/octet-stream'), filename: block.id + '.compressed.ply' });
      asset.on('load', () => {
        const entity = new pc.Entity(block.id);
        entity.addComponent('gsplat', { asset });
        entity.enabled = false;
        holder.addChild(entity);
        clip.entities[i] = entity;
        if (--left === 0) {
          const period = clip.times[clip.times.length - 1] + 1 / Number(document.body.dataset.clipFps || 25);
          let t = 0;
          showClip(hold !== null ? Math.min(Math.max(Number(hold), 0), clip.entities.length - 1) : 0);
          if (hold === null) {
            app.on('update', (dt) => {
              t = (t + dt) % period;
              let index = 0;
              while (index + 1 < clip.times.length && clip.times[index + 1] <= t) ++index;
              showClip(index);
            });
          }
          done();
        }
      });
      asset.on('error', (e) => { window.failed = block.id + ': ' + e; });
      app.assets.add(asset);
      app.assets.load(asset);
    });
  };
  let pending = 3;
  const ready = () => {
    if (--pending > 0) return;
    let frames = 0;
    app.on('frameend', () => { if (++frames === 30) window.done = true; });
  };
  const gaussians = document.getElementById('gaussians') || clipBlocks.length;
  const both = document.getElementById('mesh') && gaussians;
  load('mesh', both ? -0.13 : 0, (asset, entity) => {
    if (asset && asset.resource.animations.length) {
      // Loop the tracked sequence on the head node.
      entity.addComponent('anim', { activate: true });
      entity.anim.assignAnimation('tracked', asset.resource.animations[0].resource);
    }
    ready();
  });
  load('gaussians', both ? 0.13 : 0, () => ready());
  loadClip(both ? 0.13 : 0, () => ready());
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
  html += "<script>" + InlineScriptText(engine) + "</script>\n</head><body data-clip-fps=\"" +
          std::to_string(options.clip_fps) + "\">\n<canvas id=\"view\"></canvas>\n";
  std::vector<std::string> shown;  // what the page shows, left to right
  const auto inline_file = [&](const fs::path& path, const std::string& attributes, std::string* block) {
    std::string bytes;
    if (path.empty() || !ReadFileToString(path, &bytes).ok()) return false;
    *block = "<script " + attributes + " type=\"application/octet-stream\">" + Base64(bytes) + "</script>\n";
    return true;
  };
  std::string block;
  if (inline_file(options.mesh_glb, "id=\"mesh\"", &block)) {
    html += block;
    shown.push_back("the mesh avatar, playing the tracked sequence");
  }
  if (options.clip_times.size() != options.clip_files.size())
    return Status::InvalidArgument("export: the viewer's clip has " + std::to_string(options.clip_files.size()) +
                                   " files but " + std::to_string(options.clip_times.size()) + " times");
  for (size_t i = 0; i < options.clip_files.size(); ++i) {
    char attributes[96];
    std::snprintf(attributes, sizeof(attributes), "id=\"clip%zu\" data-clip-time=\"%.6f\"", i, options.clip_times[i]);
    if (!inline_file(options.clip_files[i], attributes, &block))
      return Status::NotFound("export: the viewer's clip frame " + options.clip_files[i].string() + " is missing");
    html += block;
  }
  const int clip_inlined = int(options.clip_files.size());
  if (clip_inlined > 0) {
    shown.push_back("the Gaussian avatar playing the baked clip" +
                    (clip_inlined < options.clip_frames
                         ? " (its first " + std::to_string(clip_inlined) + " of " + std::to_string(options.clip_frames) +
                               " frames, the whole clip in clip/)"
                         : std::string()));
  } else if (inline_file(options.gaussians_glb, "id=\"gaussians\"", &block)) {
    html += block;
    shown.push_back("the Gaussian avatar");
  }
  if (shown.empty()) return Status::NotFound("export: the viewer has no avatar to show (no mesh or Gaussian GLB)");
  const std::string legend = shown.size() == 2 ? "Left: " + shown[0] + ". Right: " + shown[1] + "."
                                               : std::string(1, char(std::toupper(shown[0][0]))) + shown[0].substr(1) + ".";
  html += "<div id=\"legend\">" + HtmlEscape(legend) + " Drag to turn, wheel to zoom.</div>\n";
  html += std::string("<script>") + kViewerScript + "</script>\n</body></html>\n";
  HF_RETURN_IF_ERROR(EnsureDirectory(out_dir));
  return WriteFileAtomic(out_dir / "index.html", html);
}

}  // namespace headforge
