#include "export/report.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <sstream>

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "avatar/model_folder.h"
#include "avatar/model_table.h"
#include "capture/capture_io.h"
#include "core/camera_set.h"
#include "core/json_io.h"
#include "export/html_util.h"
#include "reconstruction/tracking_io.h"

namespace headforge {
namespace {

// An <img> holding `image` as an inlined JPEG, `width` pixels wide at most.
std::string InlineImage(const cv::Mat& image, int width, const std::string& caption) {
  cv::Mat shown = image;
  if (image.cols > width) cv::resize(image, shown, cv::Size(width, image.rows * width / image.cols), 0, 0, cv::INTER_AREA);
  std::vector<unsigned char> jpeg;
  cv::imencode(".jpg", shown, jpeg, {cv::IMWRITE_JPEG_QUALITY, 85});
  return "<figure><img src=\"data:image/jpeg;base64," + Base64(jpeg) + "\" alt=\"" + HtmlEscape(caption) +
         "\"><figcaption>" + HtmlEscape(caption) + "</figcaption></figure>";
}

std::string Number(double value, int digits) {
  char text[64];
  std::snprintf(text, sizeof(text), "%.*f", digits, value);
  return text;
}

// JSON safe to put inside <script>.
std::string ScriptJson(const nlohmann::json& data) { return InlineScriptText(data.dump()); }

std::vector<nlohmann::json> JsonLines(const fs::path& path) {
  std::vector<nlohmann::json> lines;
  std::ifstream in(path);
  for (std::string line; std::getline(in, line);) {
    if (line.empty()) continue;
    try {
      lines.push_back(nlohmann::json::parse(line));
    } catch (const nlohmann::json::exception&) {
      // A line cut short by a kill: the rest of the log is still worth showing.
    }
  }
  return lines;
}

std::string StagesSection(const fs::path& workspace) {
  nlohmann::json manifest;
  std::string html = "<h2>Stages</h2>";
  if (!ReadJson(workspace / "workspace.json", &manifest).ok()) return html + "<p>No workspace.json.</p>";
  html += "<table><tr><th>stage</th><th>status</th><th>wall time</th><th>summary</th></tr>";
  for (const auto& stage : manifest.value("stages", nlohmann::json::array())) {
    const std::string name = stage.value("name", "");
    if (name == "export") {
      html += "<tr><td>export</td><td>writing this report</td><td></td><td></td></tr>";
      continue;
    }
    html += "<tr><td>" + HtmlEscape(name) + "</td><td>" + HtmlEscape(stage.value("status", "")) +
            "</td><td class=\"num\">" + Number(stage.value("wall_time_s", 0.0), 1) + " s</td><td>" +
            HtmlEscape(stage.value("message", "")) + "</td></tr>";
  }
  return html + "</table>";
}

// Six frames spread over the first camera, with their landmarks and the mask's outline.
std::string CaptureSection(const IngestedCapture& capture) {
  std::string html = "<h2>Capture</h2><p>" + std::to_string(capture.cameras.size()) + " camera(s), " +
                     std::to_string(capture.num_frames()) + " frames each; landmarks in green, the head mask's " +
                     "outline in yellow.</p><div class=\"row\">";
  if (capture.cameras.empty()) return html + "</div>";
  const IngestedCamera& cam = capture.cameras.front();
  const int n = std::min<int>(6, int(cam.frames.size()));
  for (int k = 0; k < n; ++k) {
    const IngestedFrame& f = cam.frames[size_t(k) * cam.frames.size() / size_t(n)];
    cv::Mat image = cv::imread(capture.FramePath(cam.name, f.index).string(), cv::IMREAD_COLOR);
    const cv::Mat mask = cv::imread(capture.MaskPath(cam.name, f.index).string(), cv::IMREAD_GRAYSCALE);
    if (image.empty()) continue;
    const int thick = std::max(1, image.cols / 256);
    if (!mask.empty()) {
      std::vector<std::vector<cv::Point>> outline;
      cv::findContours(mask > 128, outline, cv::RETR_EXTERNAL, cv::CHAIN_APPROX_SIMPLE);
      cv::drawContours(image, outline, -1, cv::Scalar(0, 220, 255), thick);
    }
    if (f.landmarks)
      for (const cv::Point2f& p : *f.landmarks) cv::circle(image, p, thick + 1, cv::Scalar(60, 220, 60), cv::FILLED);
    html += InlineImage(image, 200, cam.name + " frame " + std::to_string(f.index));
  }
  return html + "</div>";
}

// Every registered view's camera centre in the head frame.
nlohmann::json CameraData(const fs::path& workspace) {
  CameraSet cameras;
  if (!CameraSet::Read(workspace / "cameras_head.json", &cameras).ok()) return nullptr;
  nlohmann::json points = nlohmann::json::array();
  for (const CameraView& v : cameras.views)
    if (v.registered) {
      const Eigen::Vector3d c = v.Centre();
      points.push_back({{"x", c.x()}, {"y", c.y()}, {"z", c.z()}, {"camera", v.camera}, {"frame", v.frame}});
    }
  return {{"mode", cameras.mode}, {"points", points}};
}

// Tracking: residuals, and the six blendshapes that move most.
nlohmann::json TrackingData(const fs::path& workspace) {
  TrackingFile tracking;
  if (!ReadTracking(workspace / "tracking.json", &tracking).ok() || tracking.frames.empty()) return nullptr;
  nlohmann::json residual = nlohmann::json::array();
  for (const TrackedFrame& f : tracking.frames) residual.push_back({{"x", f.frame}, {"y", f.residual_px}});
  const size_t e = tracking.expression_names.size();
  std::vector<std::pair<double, size_t>> spread;
  for (size_t k = 0; k < e; ++k) {
    double sum = 0, sq = 0;
    for (const TrackedFrame& f : tracking.frames) sum += f.expression[Eigen::Index(k)], sq += std::pow(f.expression[Eigen::Index(k)], 2);
    const double mean = sum / double(tracking.frames.size());
    spread.emplace_back(sq / double(tracking.frames.size()) - mean * mean, k);
  }
  std::sort(spread.rbegin(), spread.rend());
  nlohmann::json curves = nlohmann::json::array();
  for (size_t i = 0; i < std::min<size_t>(6, spread.size()); ++i) {
    nlohmann::json points = nlohmann::json::array();
    for (const TrackedFrame& f : tracking.frames) points.push_back({{"x", f.frame}, {"y", f.expression[Eigen::Index(spread[i].second)]}});
    curves.push_back({{"name", tracking.expression_names[spread[i].second]}, {"points", points}});
  }
  return {{"residual", residual}, {"curves", curves}};
}

// Training: the loss and the held-out PSNR against wall time.
nlohmann::json TrainingData(const fs::path& model) {
  nlohmann::json loss = nlohmann::json::array(), held = nlohmann::json::array();
  for (const nlohmann::json& line : JsonLines(model / "stats.jsonl")) {
    // The gan-avatar model's lines name the generator's loss, or the warm-up's L1.
    std::string key = "loss";
    if (!line.contains(key)) key = line.value("phase", "") == "adversarial" ? "loss_g" : "recon_l1";
    if (line.contains(key)) loss.push_back({{"x", line.value("seconds", 0.0) / 60}, {"y", line[key]}});
    if (line.contains("test_psnr_masked"))
      held.push_back({{"x", line.value("seconds", 0.0) / 60}, {"y", line["test_psnr_masked"]}});
  }
  return {{"loss", loss}, {"held_out", held}};
}

// Accuracy against time: the rows `headforge bench train` left in the workspace.
nlohmann::json BenchData(const fs::path& workspace) {
  nlohmann::json bench = nlohmann::json::array();
  if (fs::is_directory(workspace / "bench_train"))
    for (const auto& entry : fs::directory_iterator(workspace / "bench_train")) {
      nlohmann::json saved;
      if (ReadJson(entry.path() / "bench.json", &saved).ok() && saved.contains("row")) bench.push_back(saved["row"]);
    }
  return bench;
}

// The rows of `headforge bench calibrate` and `bench track` results files,
// as {"calibrate": [...], "track": [...], "sources": {"calibrate": [...],
// "track": [...]}}; files that
// cannot be read go to `lacks`.
nlohmann::json BenchResults(const std::vector<fs::path>& files, std::vector<std::string>* lacks) {
  nlohmann::json out = {{"calibrate", nlohmann::json::array()},
                        {"track", nlohmann::json::array()},
                        {"sources", {{"calibrate", nlohmann::json::array()}, {"track", nlohmann::json::array()}}}};
  for (const fs::path& file : files) {
    nlohmann::json results;
    if (Status s = ReadJson(file, &results); !s.ok()) {
      lacks->push_back("bench results " + file.string() + " unreadable: " + s.message());
      continue;
    }
    const std::string bench = results.value("bench", "");
    const char* rows = bench == "calibrate" ? "settings" : bench == "track" ? "tracks" : nullptr;
    if (!rows || !results.contains(rows) || !results[rows].is_array()) {
      lacks->push_back("bench results " + file.string() + " are not from headforge bench calibrate or track");
      continue;
    }
    for (const nlohmann::json& row : results[rows])
      if (row.value("ok", false)) out[bench].push_back(row);
    out["sources"][bench].push_back(file.string());
  }
  return out;
}

// The tables beside the calibration and tracking benches' charts.
std::string CalibrationBenchTable(const nlohmann::json& rows) {
  std::string html =
      "<table><tr><th>scene</th><th>setting</th><th>wall time</th><th>registered</th><th>rotation error median / "
      "max</th><th>centre error median</th><th>focal error</th><th>aligned head-frame rotation</th></tr>";
  for (const nlohmann::json& r : rows)
    html += "<tr><td>" + HtmlEscape(r.value("scene", "")) + "</td><td>" + HtmlEscape(r.value("setting", "")) +
            "</td><td class=\"num\">" + Number(r.value("seconds", 0.0), 0) + " s</td><td class=\"num\">" +
            std::to_string(r.value("registered", 0)) + "/" + std::to_string(r.value("frames", 0)) +
            "</td><td class=\"num\">" + Number(r.value("rotation_deg_median", 0.0), 3) + " / " +
            Number(r.value("rotation_deg_max", 0.0), 3) + "°</td><td class=\"num\">" +
            Number(r.value("centre_mm_median", 0.0), 2) + " mm</td><td class=\"num\">" +
            Number(100 * r.value("focal_error", 0.0), 2) + "%</td><td class=\"num\">" +
            Number(r.value("aligned_rotation_deg_median", 0.0), 2) + "°</td></tr>";
  return html + "</table>";
}
std::string TrackingBenchTable(const nlohmann::json& rows) {
  std::string html = "<table><tr><th>subject</th><th>landmark points</th><th>track time</th><th>landmark residual</th>"
                     "<th>head rotation error</th><th>blendshape error (jawOpen)</th></tr>";
  for (const nlohmann::json& r : rows) {
    const nlohmann::json mae = r.value("blendshape_mae", nlohmann::json::object());
    html += "<tr><td>" + HtmlEscape(r.value("subject", "")) + "</td><td>" + HtmlEscape(r.value("points", "")) +
            "</td><td class=\"num\">" + Number(r.value("seconds", 0.0), 0) + " s</td><td class=\"num\">" +
            Number(r.value("residual_px", 0.0), 2) + " px</td><td class=\"num\">" +
            Number(r.value("rotation_deg", 0.0), 2) + "°</td><td class=\"num\">" +
            Number(mae.value("jawOpen", 0.0), 3) + "</td></tr>";
  }
  return html + "</table>";
}

const char* const kPageStyle = R"(<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>HeadForge report</title>
<style>
body { font: 14px/1.45 system-ui, sans-serif; margin: 24px auto; max-width: 1100px; color: #222; padding: 0 16px; }
h1 { font-size: 22px; } h2 { font-size: 18px; margin-top: 32px; border-bottom: 1px solid #ddd; }
table { border-collapse: collapse; margin: 8px 0; } td, th { border: 1px solid #ddd; padding: 3px 8px; text-align: left; vertical-align: top; }
td.num { text-align: right; white-space: nowrap; }
.row { display: flex; flex-wrap: wrap; gap: 8px; } figure { margin: 0; } figcaption { font-size: 12px; color: #555; }
.chart { position: relative; height: 280px; max-width: 1000px; } .note { color: #8a5a00; }
.chart.half { flex: 1 1 440px; min-width: 0; }
video { max-width: 100%; }
</style>
)";

// Draws the charts from the page's data once Chart.js is there.
const char* const kChartScript = R"(<script>
(function () {
  const data = JSON.parse(document.getElementById('data').textContent);
  if (typeof Chart === 'undefined') { window.done = true; return; }
  Chart.defaults.animation = false;
  Chart.defaults.maintainAspectRatio = false;
  const chart = (id, config) => { const c = document.getElementById(id); if (c) new Chart(c, config); };
  const axes = (x, y) => ({ x: { type: 'linear', title: { display: true, text: x } },
                            y: { title: { display: true, text: y } } });
  if (data.cameras) chart('cameras', { type: 'scatter', data: { datasets: [
      { label: 'camera centres (x, z)', data: data.cameras.points.map(p => ({ x: p.x, y: p.z })) },
      { label: 'head', data: [{ x: 0, y: 0 }], pointRadius: 8 }] }, options: { scales: axes('x (m)', 'z (m)') } });
  if (data.cameras) chart('cameras_side', { type: 'scatter', data: { datasets: [
      { label: 'camera centres (z, y)', data: data.cameras.points.map(p => ({ x: p.z, y: p.y })) },
      { label: 'head', data: [{ x: 0, y: 0 }], pointRadius: 8 }] }, options: { scales: axes('z (m)', 'y (m)') } });
  if (data.tracking) {
    chart('residual', { type: 'line', data: { datasets: [{ label: 'median landmark residual (px)',
        data: data.tracking.residual, pointRadius: 0 }] }, options: { scales: axes('frame', 'pixels') } });
    chart('curves', { type: 'line', data: { datasets: data.tracking.curves.map(c => ({ label: c.name,
        data: c.points, pointRadius: 0 })) }, options: { scales: axes('frame', 'weight') } });
  }
  if (data.training) chart('training', { type: 'line', data: { datasets: [
      { label: 'training loss', data: data.training.loss, yAxisID: 'y', pointRadius: 0 },
      { label: 'held-out PSNR, head (dB)', data: data.training.held_out, yAxisID: 'y1' }] },
      options: { scales: { x: { type: 'linear', title: { display: true, text: 'minutes' } },
                           y: { type: 'logarithmic', title: { display: true, text: 'loss' } },
                           y1: { position: 'right', title: { display: true, text: 'dB' } } } } });
  // One dataset per group (a scene, a set of landmark points): time against error.
  const grouped = (rows, key, x, y) => {
    const groups = {};
    rows.forEach(r => { (groups[r[key]] = groups[r[key]] || []).push({ x: r[x], y: r[y] }); });
    return Object.keys(groups).map(k => ({ label: k, data: groups[k], pointRadius: 5 }));
  };
  if (data.benches.calibrate.length) chart('bench_calibrate', { type: 'scatter',
      data: { datasets: grouped(data.benches.calibrate, 'scene', 'seconds', 'rotation_deg_median') },
      options: { scales: { x: { type: 'logarithmic', title: { display: true, text: 'calibrate + align wall time (s)' } },
                           y: { type: 'logarithmic', title: { display: true, text: 'camera rotation error, median (deg)' } } } } });
  if (data.benches.track.length) chart('bench_track', { type: 'scatter',
      data: { datasets: grouped(data.benches.track, 'points', 'seconds', 'rotation_deg') },
      options: { scales: axes('track wall time (s)', 'head rotation error (deg)') } });
  if (data.bench.length) chart('bench', { type: 'scatter', data: { datasets: data.bench.map(r => ({
      label: (r.model === 'gan-avatar' ? 'gan-avatar: ' : '') + (r.what || r.variant),
      data: [{ x: r.seconds / 60, y: r.psnr_masked }], pointRadius: 6, pointStyle: r.model === 'gan-avatar' ? 'triangle' : 'circle' })) },
      options: { scales: axes('training time (minutes)', 'held-out PSNR, head (dB)') } });
  window.done = true;
})();
</script>
</body></html>
)";

// The held-out scores, and the best and worst held-out frames of `model`.
std::string EvaluationSection(const nlohmann::json& eval, const fs::path& model, const nlohmann::json& faces) {
  std::string html;
  const nlohmann::json mean = eval.value("mean", nlohmann::json::object());
  html += "<h2>Evaluation</h2><p>Held out: " + HtmlEscape(eval.value("held_out_frames", std::string("?"))) +
          " frames, background " + Number(eval.value("background", 0.5), 1) + ".</p><table>"
          "<tr><th></th><th>PSNR</th><th>SSIM</th><th>L1</th><th>sharpness, render / frame</th><th>SD</th></tr>"
          "<tr><td>held-out, over the head</td><td class=\"num\">" + Number(mean.value("psnr_masked", 0.0), 2) +
          " dB</td><td class=\"num\">" + Number(mean.value("ssim_masked", 0.0), 3) + "</td><td class=\"num\">" +
          Number(mean.value("l1_masked", 0.0), 4) + "</td><td class=\"num\">" +
          Number(mean.value("sharpness", 0.0), 2) + " / " + Number(mean.value("sharpness_truth", 0.0), 2) +
          "</td><td class=\"num\">" + Number(mean.value("sd", 0.0), 2) +
          "</td></tr><tr><td>held-out, whole frame</td><td class=\"num\">" + Number(mean.value("psnr", 0.0), 2) +
          " dB</td><td class=\"num\">" + Number(mean.value("ssim", 0.0), 3) +
          "</td><td></td><td></td><td></td></tr></table><p>Sharpness: the mean gradient magnitude over the head, "
          "in grey levels per pixel; SD, the render's minus the frame's (negative: blurrier). LPIPS is not "
          "computed: it needs ImageNet-pretrained weights, which are not available here.</p>";
  if (faces.value("scored", 0) == 0 && faces.contains("views"))
    html += "<p class=\"note\">Identity (CSIM) and landmark distance (F-LMD) not measured: the face detector "
            "found no face in the " + std::to_string(faces.value("views", 0)) +
            " held-out frames (too small, or turned away).</p>";
  else if (faces.contains("mean_csim"))
    html += "<p>Identity (CSIM): <b>" + Number(faces["mean_csim"].get<double>(), 3) +
            "</b>, the cosine of a face-recognition network's descriptors of render and frame (face-api's, dlib's "
            "ResNet; 1 is the same face; two frames of one person score about 0.99, two people 0.80-0.92; not the "
            "ArcFace CSIM papers give). Landmark distance (F-LMD): <b>" +
            Number(faces.value("mean_flmd_px", 0.0), 2) + " px</b>, the mean distance between the 68 landmarks of "
            "frame and render, in pixels of the " + std::to_string(faces.value("image_size", 0)) +
            " px held-out images. Over " + std::to_string(faces.value("scored", 0)) + " of " +
            std::to_string(faces.value("views", 0)) + " held-out views (those whose frame shows a face).</p>";
  else if (faces.contains("missing"))
    html += "<p class=\"note\">Identity (CSIM) and landmark distance (F-LMD) not measured: " +
            HtmlEscape(faces["missing"].get<std::string>()) + ".</p>";
  std::vector<nlohmann::json> views = eval.value("views", std::vector<nlohmann::json>());
  std::sort(views.begin(), views.end(), [](const nlohmann::json& a, const nlohmann::json& b) {
    return a.value("psnr_masked", 0.0) > b.value("psnr_masked", 0.0);
  });
  if (!views.empty()) {
    html += "<p>Best and worst held-out frames (render | frame | error ×4):</p><div class=\"row\">";
    std::vector<size_t> picks = {0, 1, views.size() - 2, views.size() - 1};
    picks.erase(std::unique(picks.begin(), picks.end()), picks.end());
    for (size_t i : picks) {
      if (i >= views.size()) continue;
      char name[64];
      std::snprintf(name, sizeof(name), "%s_%06d.png", views[i].value("camera", std::string("cam0")).c_str(),
                    views[i].value("frame", 0));
      const cv::Mat strip = cv::imread((model / "held_out" / name).string(), cv::IMREAD_COLOR);
      if (!strip.empty())
        html += InlineImage(strip, 520, "frame " + std::to_string(views[i].value("frame", 0)) + ": " +
                                            Number(views[i].value("psnr_masked", 0.0), 2) + " dB");
    }
    html += "</div>";
  }
  return html;
}

// The videos and files export wrote beside the page.
std::string ExportedSection(const std::vector<std::string>& exported) {
  std::string videos, files, html;
  for (const std::string& f : exported) {
    files += "<li><code>" + HtmlEscape(f) + "</code></li>";
    if (f.size() > 4 && f.compare(f.size() - 4, 4, ".mp4") == 0)
      videos += "<figure><video controls muted preload=\"metadata\" src=\"" + HtmlEscape(f) + "\"></video><figcaption>" +
                HtmlEscape(f) + "</figcaption></figure>";
  }
  if (!videos.empty()) html += "<h2>Videos</h2><div class=\"row\">" + videos + "</div>";
  if (!files.empty()) html += "<h2>Exported files</h2><ul>" + files + "</ul>";
  return html;
}

}  // namespace

Status WriteReport(const fs::path& workspace, const fs::path& out_dir, const ReportOptions& options,
                   std::string* note) {
  IngestedCapture capture;
  HF_RETURN_IF_ERROR(ReadIngestedCapture(workspace, &capture));
  nlohmann::json data = nlohmann::json::object();
  std::vector<std::string> lacks;
  if (nlohmann::json cameras = CameraData(workspace); !cameras.is_null()) data["cameras"] = cameras;
  if (nlohmann::json tracking = TrackingData(workspace); !tracking.is_null()) data["tracking"] = tracking;
  // The model trained last (the one export takes).
  const fs::path latest = LatestModelFolder(workspace);
  const fs::path model = latest.empty() ? kGaussianStyle.Dir(workspace) : latest;
  nlohmann::json eval;
  const bool trained = ReadJson(model / "eval.json", &eval).ok();
  if (trained)
    data["training"] = TrainingData(model);
  else
    lacks.push_back("no trained model (run headforge train): no training or evaluation sections");
  data["bench"] = BenchData(workspace);
  data["benches"] = BenchResults(options.bench_results, &lacks);

  std::string html = kPageStyle;
  std::string chart_js;
  if (!options.chart_js.empty() && ReadFileToString(options.chart_js, &chart_js).ok() && !chart_js.empty()) {
    html += "<script>" + InlineScriptText(chart_js) + "</script>\n";
  } else {
    lacks.push_back("no charting library (scripts/install_deps.sh installs Chart.js): tables and images only");
  }
  html += "<script id=\"data\" type=\"application/json\">" + ScriptJson(data) + "</script>\n</head><body>\n";
  html += "<h1>HeadForge report: " + HtmlEscape(workspace.filename().string()) + "</h1>";
  if (!lacks.empty()) {
    html += "<p class=\"note\">";
    for (const std::string& l : lacks) html += HtmlEscape(l) + ". ";
    html += "</p>";
  }
  html += StagesSection(workspace);
  html += CaptureSection(capture);
  html += "<h2>Cameras</h2><p>Each view's camera centre in the head frame (metres; +y up, the face looks toward "
          "+z), seen from above (left) and from the side (right).</p><div class=\"row\"><div class=\"chart "
          "half\"><canvas id=\"cameras\"></canvas></div><div class=\"chart half\"><canvas "
          "id=\"cameras_side\"></canvas></div></div>";
  html += "<h2>Tracking</h2><p>The median landmark residual per frame (pixels), and the six blendshapes that "
          "move most.</p><div class=\"chart\"><canvas id=\"residual\"></canvas></div>"
          "<div class=\"chart\"><canvas id=\"curves\"></canvas></div>";
  if (trained) {
    html += "<h2>Training</h2><p>The training loss and the held-out PSNR over the head against wall time.</p>"
            "<div class=\"chart\"><canvas id=\"training\"></canvas></div>";
    nlohmann::json faces;
    (void)ReadJson(out_dir / "face_metrics.json", &faces);
    html += EvaluationSection(eval, model, faces);
  }
  html += "<h2>Accuracy against time</h2>";
  const nlohmann::json& benches = data["benches"];
  const auto sources = [&](const char* bench) {
    std::string text;
    for (const auto& f : benches["sources"][bench]) text += (text.empty() ? "" : ", ") + f.get<std::string>();
    return HtmlEscape(text);
  };
  if (!benches["calibrate"].empty())
    html += "<h3>Cameras</h3><p>Each setting of <code>headforge bench calibrate</code> on simulated scenes: the "
            "wall time of calibrate and align against the median rotation error of its cameras after the best "
            "similarity to the simulator's truth (one colour a scene). From " + sources("calibrate") +
            ".</p><div class=\"chart\"><canvas id=\"bench_calibrate\"></canvas></div>" +
            CalibrationBenchTable(benches["calibrate"]);
  if (!benches["track"].empty())
    html += "<h3>Tracking</h3><p>Each subject of <code>headforge bench track</code> (talking_static with another "
            "simulated face): the track stage's wall time against its head rotation error, with the plain landmark "
            "points and with their identity columns. From " + sources("track") +
            ".</p><div class=\"chart\"><canvas id=\"bench_track\"></canvas></div>" +
            TrackingBenchTable(benches["track"]);
  if (benches["calibrate"].empty() && benches["track"].empty())
    html += "<p>No <code>headforge bench calibrate</code> or <code>bench track</code> results: run them with "
            "<code>--out WORKSPACE/bench_calibrate</code> and <code>--out WORKSPACE/bench_track</code> (or give "
            "export <code>--bench-results FILE</code>) to see what the cameras' and the tracking's accuracy cost "
            "here.</p>";
  html += "<h3>Training</h3>";
  if (data["bench"].empty()) {
    html += "<p>No <code>headforge bench train</code> results in this workspace; the training curve above is this "
            "run's own.</p>";
  } else {
    html += "<p>Held-out PSNR over the head against training time for each variant and each rung of the ladder "
            "<code>headforge bench train</code> trained on this workspace (a preset's rung is the preset as "
            "<code>headforge run</code> trains it).</p><div class=\"chart\"><canvas id=\"bench\"></canvas></div>"
            "<table><tr><th>variant or rung</th><th>model</th><th>steps</th><th>training time</th>"
            "<th>held-out PSNR / SSIM, head</th><th>held-out PSNR, frame</th></tr>";
    std::vector<nlohmann::json> rows(data["bench"].begin(), data["bench"].end());
    std::sort(rows.begin(), rows.end(), [](const nlohmann::json& a, const nlohmann::json& b) {
      return a.value("seconds", 0.0) < b.value("seconds", 0.0);
    });
    for (const nlohmann::json& r : rows)
      html += "<tr><td>" + HtmlEscape(r.value("what", r.value("variant", std::string("?")))) + "</td><td>" +
              HtmlEscape(r.value("model", kGaussianStyle.Name())) + "</td><td class=\"num\">" +
              std::to_string(r.value("steps", 0)) + "</td><td class=\"num\">" +
              Number(r.value("seconds", 0.0) / 60, 1) + " min</td><td class=\"num\">" +
              Number(r.value("psnr_masked", 0.0), 2) + " dB / " + Number(r.value("ssim_masked", 0.0), 3) +
              "</td><td class=\"num\">" + Number(r.value("psnr", 0.0), 2) + " dB</td></tr>";
    html += "</table>";
  }
  html += ExportedSection(options.exported);
  html += kChartScript;
  HF_RETURN_IF_ERROR(WriteFileAtomic(out_dir / "report.html", html));
  note->clear();
  for (const std::string& l : lacks) *note += (note->empty() ? "" : "; ") + l;
  return Status::Ok();
}

}  // namespace headforge
