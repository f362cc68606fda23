// The drive page (export --formats drive): the Gaussian blendshapes posed in
// the page by a recorded take or the webcam. Its face basis against the
// face mesh ingest found; in headless Chromium, where installed: its
// drawing against headforge render, the takes it plays, and a fake webcam
// fed with the capture's own frames, its weights against the simulator's
// truth and track's.
#include <cctype>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>

#include <nlohmann/json.hpp>

#include "tests/train_fixture.h"

namespace headforge {
namespace {

class DrivePage : public TrainStage {
 protected:
  static void SetUpTestSuite() {
    CopyReference("drive_reference");
    // The blendshapes as fitted to the networks, a quarter of them pruned:
    // the page draws whichever it is given (their refinement has its own
    // tests).
    exported_ = Headforge({"export", "--workspace", reference_.string(), "--formats", "mesh", "blendshapes", "drive",
                           "--texture-size", "128", "--bake-views", "8", "--blendshape-refine-steps", "0",
                           "--blendshape-prune", "0.25"});
  }
  static Result exported_;
};
Result DrivePage::exported_;

// The page's data block (the JSON inlined in drive/index.html).
nlohmann::json PageData(const fs::path& page) {
  const std::string html = Slurp(page);
  const std::string open = "<script id=\"drive-data\" type=\"application/json\">";
  const size_t begin = html.find(open);
  if (begin == std::string::npos) return nlohmann::json();
  const size_t start = begin + open.size(), end = html.find("</script>", start);
  return nlohmann::json::parse(html.substr(start, end - start), nullptr, false);
}

// The face basis posed by frame k's tracked weights and pose lands on the
// face mesh ingest found in frame k: the median distance in pixels.
double BasisToMeshPixels(const nlohmann::json& basis, const nlohmann::json& tracking, const nlohmann::json& landmarks,
                         int frame) {
  const auto& names = basis["expression_names"];
  const auto& weights = tracking["frames"][frame]["expression"];
  std::vector<double> pose;
  for (const auto& f : basis["frames"])
    if (f["frame"] == frame) pose = f["cam_from_head"].get<std::vector<double>>();
  const auto& mesh = landmarks["cameras"]["cam0"][frame]["mesh"];
  const auto& c = basis["camera"];
  std::vector<double> distances;
  for (size_t i = 0; i < 468; ++i) {
    double p[3];
    for (int a = 0; a < 3; ++a) {
      p[a] = basis["neutral"][i][a].get<double>();
      for (size_t k = 0; k < names.size(); ++k)
        p[a] += weights[names[k].get<std::string>()].get<double>() * basis["offsets"][k][i][a].get<double>();
    }
    double q[3];
    for (int r = 0; r < 3; ++r) q[r] = pose[4 * r] * p[0] + pose[4 * r + 1] * p[1] + pose[4 * r + 2] * p[2] + pose[4 * r + 3];
    const double u = c["fx"].get<double>() * q[0] / q[2] + c["cx"].get<double>();
    const double v = c["fy"].get<double>() * q[1] / q[2] + c["cy"].get<double>();
    distances.push_back(std::hypot(u - mesh[3 * i].get<double>(), v - mesh[3 * i + 1].get<double>()));
  }
  std::nth_element(distances.begin(), distances.begin() + 234, distances.end());
  return distances[234];
}

TEST_F(DrivePage, WritesThePageAndAFaceBasisThatLandsOnTheFaceMesh) {
  ASSERT_EQ(exported_.code, 0) << exported_.err;
  const fs::path drive = reference_ / "export" / "drive";
  ASSERT_TRUE(fs::exists(drive / "index.html"));
  nlohmann::json basis, tracking, landmarks;
  ASSERT_TRUE(ReadJson(drive / "face_basis.json", &basis).ok());
  ASSERT_TRUE(ReadJson(reference_ / "tracking.json", &tracking).ok());
  ASSERT_TRUE(ReadJson(reference_ / "landmarks.json", &landmarks).ok());
  ASSERT_EQ(basis["neutral"].size(), 468u);
  ASSERT_EQ(basis["offsets"].size(), 53u);
  EXPECT_EQ(basis["expression_names"], tracking["expression_names"]);
  EXPECT_EQ(basis["oval"].size(), 36u);
  // The weights' prior: the tracked weights' mean and spread over the frames
  // the avatar trained on (the capture's last ones held out, as training
  // holds them out on a fixed camera), recomputed here.
  {
    nlohmann::json layout;
    ASSERT_TRUE(ReadJson(reference_ / "export" / "blendshapes" / "blendshapes.json", &layout).ok());
    const int frames = int(tracking["frames"].size());
    const int trained = frames - std::max(1, int(std::lround(layout["data"]["holdout"].get<double>() * frames)));
    const nlohmann::json& prior = basis["expression_prior"];
    ASSERT_EQ(prior["frames"], trained);
    ASSERT_EQ(prior["mean"].size(), 53u);
    ASSERT_EQ(prior["spread"].size(), 53u);
    int narrow = 0;
    for (size_t k = 0; k < 53; ++k) {
      const std::string name = basis["expression_names"][k];
      double sum = 0, squares = 0;
      for (const auto& f : tracking["frames"])
        if (f["frame"].get<int>() < trained) {
          const double w = f["expression"][name];
          sum += w;
          squares += w * w;
        }
      const double mean = sum / trained, spread = std::sqrt(std::max(0.0, squares / trained - mean * mean));
      EXPECT_NEAR(prior["mean"][k].get<double>(), mean, 1e-9) << name;
      EXPECT_NEAR(prior["spread"][k].get<double>(), spread, 1e-6) << name;
      narrow += spread < 0.02;
    }
    std::printf("expression prior: %d training frames, %d of 53 weights spread under 0.02\n", trained, narrow);
  }
  // Where the tracked face model puts the mesh's points, against where the
  // face mesh found them (where ingest had the model): the embedding and
  // the tracking together.
  const bool vision = fs::exists(fs::path(DefaultVisionModelsDir()) / "facemesh.json");
  for (int frame : vision ? std::vector<int>{0, 60, 110} : std::vector<int>{}) {
    const double px = BasisToMeshPixels(basis, tracking, landmarks, frame);
    std::printf("frame %d: the face basis %.2f px (median) from the face mesh found in it\n", frame, px);
    EXPECT_LT(px, 4.0);
  }
  // The quarter giving the least light pruned: the rest draw the held-out
  // frames nearly as well.
  nlohmann::json layout;
  ASSERT_TRUE(ReadJson(reference_ / "export" / "blendshapes" / "blendshapes.json", &layout).ok());
  const nlohmann::json& pruning = layout["pruning"];
  const int fitted = pruning["gaussians_fitted"], kept = pruning["gaussians_kept"];
  const double before = layout["held_out"]["psnr_masked_fitted"], after = layout["held_out"]["psnr_masked_pruned"];
  std::printf("pruned %d of %d Gaussians (%.1f%% of the light kept): held out %.2f -> %.2f dB\n", fitted - kept, fitted,
              100 * pruning["light_kept"].get<double>(), before, after);
  EXPECT_EQ(kept, int(std::lround(0.75 * fitted)));
  EXPECT_EQ(layout["gaussians"], kept);
  EXPECT_GT(pruning["light_kept"].get<double>(), 0.9);
  EXPECT_GT(after, before - 1.0);
  EXPECT_EQ(after, layout["held_out"]["psnr_masked_blendshapes"].get<double>());  // not refined

  const nlohmann::json data = PageData(drive / "index.html");
  ASSERT_TRUE(data.is_object());
  EXPECT_EQ(data["names"], tracking["expression_names"]);
  EXPECT_EQ(data["frames"].size(), tracking["frames"].size());
  EXPECT_EQ(data["offsets_type"], "float16");
  EXPECT_EQ(data["camera"]["width"], 48);  // the avatar's training size, as render draws
  // The face mesh model inlined where installed: the webcam drives the page.
  EXPECT_EQ(data["face"].is_object(), vision);

  // Without the face mesh model the page plays takes only, and says why.
  const fs::path bare = CopyOf(reference_, Scratch("drive_bare"));
  const Result without = Headforge({"export", "--workspace", bare.string(), "--formats", "drive",
                                    "--export-vision-models", (bare / "no_models").string()});
  ASSERT_EQ(without.code, 0) << without.err;
  EXPECT_NE(without.err.find("the blendshapes of the export before, kept"), std::string::npos) << without.err;
  EXPECT_NE(without.err.find("scripts/install_deps.sh installs both"), std::string::npos) << without.err;
  EXPECT_TRUE(PageData(bare / "export" / "drive" / "index.html")["face"].is_null());
  EXPECT_TRUE(fs::exists(bare / "export" / "blendshapes" / "blendshapes.bin"));
  // No blendshapes at all: refused, naming what to export.
  fs::remove_all(bare / "export");
  const Result none = Headforge({"export", "--workspace", bare.string(), "--formats", "drive"});
  EXPECT_EQ(none.code, 1);
  EXPECT_NE(none.err.find("export --formats blendshapes drive"), std::string::npos) << none.err;
}

#ifdef HEADFORGE_BROWSER_CHECKS
// scripts/web/drive_page.cjs on the page with `extra` options; the state it wrote.
nlohmann::json OpenDrivePage(const fs::path& ws, const std::string& name, const std::string& extra, int* code,
                             fs::path* written = nullptr) {
  const fs::path out = Scratch(name);
  if (written) *written = out;
  const std::string command = std::string("'") + HEADFORGE_NODE + "' '" + HEADFORGE_TEST_SOURCE_DIR +
                              "/scripts/web/drive_page.cjs' --page '" + (ws / "export" / "drive" / "index.html").string() +
                              "' --out '" + out.string() + "' --chromium '" + HEADFORGE_CHROMIUM + "' " + extra;
  *code = std::system(command.c_str());
  nlohmann::json state;
  EXPECT_TRUE(ReadJson(out / "state.json", &state).ok()) << command;
  return state;
}

// `headforge render` of frame k through the blendshapes (driven by `drive`
// when given); the PNG's path.
fs::path RenderBlendshapes(const fs::path& ws, int frame, const std::string& name, const fs::path& drive = "") {
  const fs::path out = Scratch(name);
  std::vector<std::string> args = {"render", "--workspace", ws.string(), "--model", (ws / "export" / "blendshapes").string(),
                                   "--frames", std::to_string(frame), "--out", out.string()};
  if (!drive.empty()) args.insert(args.end(), {"--drive", drive.string()});
  const Result r = Headforge(args);
  EXPECT_EQ(r.code, 0) << r.err;
  char file[48];
  std::snprintf(file, sizeof(file), "frame_%06d%s.png", frame, drive.empty() ? "" : "_driven");
  return out / file;
}

std::string CompareOptions(const fs::path& ws, const fs::path& render, int frame, double min_psnr) {
  char mask[32];
  std::snprintf(mask, sizeof(mask), "%06d.png", frame);
  return "--compare '" + render.string() + "' --mask '" + (ws / "masks" / "cam0" / mask).string() + "' --min-psnr " +
         std::to_string(min_psnr);
}

TEST_F(DrivePage, DrawsAFrameAsRenderDoes) {
  ASSERT_EQ(exported_.code, 0) << exported_.err;
  const fs::path render = RenderBlendshapes(reference_, 110, "drive_render");
  int code = 0;
  const nlohmann::json state =
      OpenDrivePage(reference_, "drive_frame", "--frame 110 " + CompareOptions(reference_, render, 110, 45), &code);
  EXPECT_EQ(code, 0);
  EXPECT_EQ(state["frame"], 110);
  EXPECT_TRUE(state["errors"].empty()) << state["errors"];
  const double psnr = state["compare"]["psnr"];
  std::printf("the page's WebGL drawing of frame 110 against headforge render: %.1f dB (half-float target: %d)\n", psnr,
              int(state["halfFloat"].get<bool>()));
  EXPECT_GT(psnr, 45.0);  // 55.3 dB when written
}

// Pixels of a drawing that are not the white background.
cv::Mat Foreground(const fs::path& png) {
  const cv::Mat image = cv::imread(png.string());
  EXPECT_FALSE(image.empty()) << png;
  cv::Mat grey;
  cv::cvtColor(image, grey, cv::COLOR_BGR2GRAY);
  return grey < 245;
}
int Changed(const fs::path& a, const fs::path& b) {
  cv::Mat difference;
  cv::absdiff(cv::imread(a.string()), cv::imread(b.string()), difference);
  cv::Mat grey;
  cv::cvtColor(difference, grey, cv::COLOR_BGR2GRAY);
  return cv::countNonZero(grey > 20);
}

// The mesh avatar beside the Gaussians: the same camera and pose (their
// silhouettes overlap; the Gaussians hold the hair and shoulders the mesh
// does not), and its morph targets follow the same weights as the
// blendshapes (jawOpen at 0 and at 1 changes both drawings).
TEST_F(DrivePage, TheMeshAvatarFollowsTheSameWeights) {
  ASSERT_EQ(exported_.code, 0) << exported_.err;
  int code = 0;
  nlohmann::json states[2];
  fs::path dirs[2];
  for (int open : {0, 1}) {
    states[open] = OpenDrivePage(reference_, "drive_jaw" + std::to_string(open),
                                 "--frame 110 --weights '{\"jawOpen\": " + std::to_string(open) + "}'", &code,
                                 &dirs[open]);
    EXPECT_EQ(code, 0);
    EXPECT_EQ(states[open]["mesh"], "drawn");
  }
  const fs::path& shut = dirs[0];
  const fs::path& opened = dirs[1];
  const cv::Mat gaussians = Foreground(shut / "canvas.png"), mesh = Foreground(shut / "mesh.png");
  const double iou = double(cv::countNonZero(gaussians & mesh)) / cv::countNonZero(gaussians | mesh);
  const int mesh_changed = Changed(shut / "mesh.png", opened / "mesh.png");
  const int splats_changed = Changed(shut / "canvas.png", opened / "canvas.png");
  std::printf("mesh against Gaussians: silhouette IoU %.2f; jawOpen 0 -> 1 changes %d mesh and %d Gaussian pixels\n",
              iou, mesh_changed, splats_changed);
  EXPECT_GT(iou, 0.7);             // 0.83 when written
  EXPECT_GT(mesh_changed, 30);     // 100
  EXPECT_GT(splats_changed, 30);   // 97
  const auto& names = states[1]["names"];
  const size_t jaw = size_t(std::find(names.begin(), names.end(), "jawOpen") - names.begin());
  ASSERT_LT(jaw, names.size());
  EXPECT_EQ(states[1]["weights"][jaw], 1.0);
}

// blendshapes.glb (KHR_gaussian_splatting and 53 morph targets at weight 0)
// drawn by PlayCanvas through frame 110's camera, against headforge render
// of the blendshapes at the neutral expression (frame 110's weights set to 0
// in a copy of the workspace): scripts/web/compare_splats.cjs.
TEST_F(DrivePage, PlayCanvasDrawsTheBlendshapeGlbAtItsNeutralAsRenderDoes) {
  ASSERT_EQ(exported_.code, 0) << exported_.err;
  const fs::path ws = CopyOf(reference_, Scratch("drive_neutral"));
  nlohmann::json tracking;
  ASSERT_TRUE(ReadJson(ws / "tracking.json", &tracking).ok());
  for (auto& f : tracking["frames"])
    if (f["frame"] == 110)
      for (auto& [name, weight] : f["expression"].items()) weight = 0.0;
  ASSERT_TRUE(WriteJsonAtomic(ws / "tracking.json", tracking, 1).ok());
  const fs::path shapes = ws / "export" / "blendshapes";
  const std::string command = std::string("'") + HEADFORGE_NODE + "' '" + HEADFORGE_TEST_SOURCE_DIR +
                              "/scripts/web/compare_splats.cjs' --workspace '" + ws.string() + "' --frame 110 --file '" +
                              (shapes / "blendshapes.glb").string() + "' --model '" + shapes.string() +
                              "' --size 128 --min-psnr 30 --headforge '" + HEADFORGE_BINARY + "' --chromium '" +
                              HEADFORGE_CHROMIUM + "'";
  EXPECT_EQ(std::system(command.c_str()), 0) << command;
}

// tracking.json and a Live Link Face CSV played back: frame k as render
// --drive draws it (the take's expressions, the avatar's own first pose).
TEST_F(DrivePage, PlaysRecordedTakes) {
  ASSERT_EQ(exported_.code, 0) << exported_.err;
  const fs::path render = RenderBlendshapes(reference_, 110, "drive_render_driven", reference_);
  int code = 0;
  nlohmann::json state = OpenDrivePage(reference_, "drive_take",
                                       "--take '" + (reference_ / "tracking.json").string() + "' --frame 110 " +
                                           CompareOptions(reference_, render, 110, 45), &code);
  EXPECT_EQ(code, 0);
  EXPECT_EQ(state["mode"], "recorded take");
  std::printf("tracking.json played, frame 110 against render --drive: %.1f dB\n", state["compare"]["psnr"].get<double>());

  // The CSV as Live Link Face writes it: ARKit's names (one browInnerUp and
  // one cheekPuff where the face model has a left and a right), the head's
  // and eyes' angles, a blendshape the avatar lacks, one of the avatar's
  // missing; row 1 is frame 110, row 2 has weights outside [0, 1].
  nlohmann::json tracking;
  ASSERT_TRUE(ReadJson(reference_ / "tracking.json", &tracking).ok());
  const auto& names = tracking["expression_names"];
  const auto& w = tracking["frames"][110]["expression"];
  std::vector<std::string> header = {"Timecode", "BlendShapeCount"};
  std::vector<double> row;
  std::map<std::string, double> expected;
  for (const auto& n : names) {
    std::string name = n.get<std::string>(), arkit = name;
    arkit[0] = char(std::toupper(arkit[0]));
    if (arkit.size() > 2 && arkit.compare(arkit.size() - 2, 2, "_L") == 0) arkit = arkit.substr(0, arkit.size() - 2) + "Left";
    if (arkit.size() > 2 && arkit.compare(arkit.size() - 2, 2, "_R") == 0) arkit = arkit.substr(0, arkit.size() - 2) + "Right";
    double value = w[name].get<double>();
    for (const char* single : {"BrowInnerUp", "CheekPuff"})
      if (arkit.rfind(single, 0) == 0) {
        const std::string base = name.substr(0, name.size() - 2);
        value = 0.5 * (w[base + "_L"].get<double>() + w[base + "_R"].get<double>());
        arkit = single;
      }
    // A blendshape the take does not have stays 0.
    if (name == "noseSneer_L") value = 0;
    expected[name] = value;
    if (name == "noseSneer_L" || std::find(header.begin(), header.end(), arkit) != header.end()) continue;
    header.push_back(arkit);
    row.push_back(value);
  }
  for (const char* extra : {"TongueOut", "HeadYaw", "HeadPitch", "HeadRoll", "LeftEyeYaw"}) {
    header.push_back(extra);
    row.push_back(0.3);
  }
  const fs::path csv = Scratch("drive_take.csv");
  {
    std::ofstream file(csv);
    for (size_t i = 0; i < header.size(); ++i) file << (i ? "," : "") << header[i];
    file << "\n00:00:00:00.000," << row.size() - 5;
    for (size_t i = 0; i < row.size(); ++i) file << "," << 0.0;
    file << "\n00:00:00:01.000," << row.size() - 5;
    for (double v : row) file << "," << v;
    file << "\n00:00:00:02.000," << row.size() - 5;
    for (size_t i = 0; i < row.size(); ++i) file << "," << (header[i + 2] == "JawOpen" ? 1.7 : header[i + 2] == "EyeBlinkLeft" ? -0.3 : 0.0);
    file << "\n";
  }
  state = OpenDrivePage(reference_, "drive_csv", "--take '" + csv.string() + "' --frame 1 " +
                                                     CompareOptions(reference_, render, 110, 35), &code);
  EXPECT_EQ(code, 0);
  for (size_t k = 0; k < names.size(); ++k)
    EXPECT_NEAR(state["weights"][k].get<double>(), expected[names[k].get<std::string>()], 1e-6) << names[k];
  EXPECT_EQ(state["unknown"], nlohmann::json::array({"TongueOut"}));
  std::printf("the CSV's row for frame 110 against render --drive: %.1f dB (its brows and cheeks one weight each)\n",
              state["compare"]["psnr"].get<double>());
  // Outside [0, 1]: clamped; every other blendshape at 0.
  state = OpenDrivePage(reference_, "drive_csv_range", "--take '" + csv.string() + "' --frame 2", &code);
  EXPECT_EQ(code, 0);
  for (size_t k = 0; k < names.size(); ++k)
    EXPECT_EQ(state["weights"][k].get<double>(), names[k] == "jawOpen" ? 1.0 : 0.0) << names[k];
}

// A recorded video of the capture's own frames drives the page (the first
// frame held for two seconds: the page calibrates on its first ten solves;
// then the clip, two seconds of black, the first frame again), every fourth
// frame solved in turn at the video's pace, so the figures do not depend on
// the machine's load: the page's weights against the simulator's truth, its
// head's turn against the truth's, its last drawing (the first frame, found
// again) against render's; in the black the face is lost, and the avatar is
// back at its rest (the capture's first expression and pose) when the face
// returns. Then the same frames as a fake webcam, played in real time: the
// page's camera path reaches the solve.
TEST_F(DrivePage, AVideoAndTheWebcamDriveIt) {
  ASSERT_EQ(exported_.code, 0) << exported_.err;
  const fs::path out = Scratch("drive_video");
  const std::string command =
      std::string("'") + HEADFORGE_NODE + "' '" + HEADFORGE_TEST_SOURCE_DIR + "/scripts/web/drive_webcam_check.cjs' --workspace '" +
      reference_.string() + "' --out '" + out.string() + "' --video --fps 6.25 --hold 2 --blank 2 --truth '" +
      (SharedSimulation("talking_static", 125) / "ground_truth.json").string() + "' --headforge '" + HEADFORGE_BINARY +
      "' --chromium '" + HEADFORGE_CHROMIUM + "' --max-weight-error 0.15 --max-rotation-deg 5 --min-psnr 30";
  EXPECT_EQ(std::system(command.c_str()), 0) << command;
  nlohmann::json check;
  ASSERT_TRUE(ReadJson(out / "check.json", &check).ok());
  const nlohmann::json& s = check["summary"];
  EXPECT_EQ(s["video_frames"].get<int>(), 62);  // 50 + 125 + 50 + 25 frames at 25 a second, every fourth
  EXPECT_EQ(s["calibration"].get<int>(), 10);
  EXPECT_GE(s["compared"].get<int>(), 30);  // 35 when written: the clip's 31 and the returned first frame's
  for (const char* name : {"jawOpen", "eyeBlink_L", "eyeBlink_R"})
    EXPECT_LT(s["mae_truth"][name].get<double>(), 0.15) << name;  // 0.061-0.100 when written (track: 0.029-0.057)
  EXPECT_LT(s["turn_error_deg_median"]["page"].get<double>(), 3.0);  // 1.57 (track 1.39)
  EXPECT_GT(s["psnr_last"].get<double>(), 35.0);                     // 48.2: the rest, drawn as render draws it
  ASSERT_EQ(s["lost_episodes"].size(), 1u);
  const nlohmann::json& lost = s["lost_episodes"][0];
  std::printf("face lost for %.2f s of the video: the avatar %.4f from its rest when it returned\n",
              lost["seconds"].get<double>(), lost["off_rest"].get<double>());
  EXPECT_NEAR(lost["seconds"].get<double>(), 2.0, 0.2);
  EXPECT_LT(lost["off_rest"].get<double>(), 1e-6);
  EXPECT_GT(s["solves"].get<int>(), lost["solves_before"].get<int>());  // found again after

  // The webcam: how many of its frames the page solves depends on the
  // machine; that they reach the solve does not.
  int code = 0;
  const nlohmann::json webcam =
      OpenDrivePage(reference_, "drive_webcam", "--webcam '" + (out / "camera.y4m").string() + "' --seconds 4", &code);
  EXPECT_EQ(code, 0) << webcam.dump().substr(0, 2000);
  EXPECT_EQ(webcam.value("mode", ""), "webcam");
  EXPECT_GE(webcam.value("solves", nlohmann::json::array()).size(), 3u);
}
#endif

}  // namespace
}  // namespace headforge
