// The export stage on the trained reference: every format written and read
// back by the tools that open it (glTF-Validator, three.js, PlayCanvas,
// splat-transform, Chromium), a kill and a full disk mid-export, the
// report's plots and links; and a workspace never trained.
#include <algorithm>
#include <cmath>
#include <cstring>

#include "tests/train_fixture.h"

namespace headforge {
namespace {

class ExportStage : public TrainStage {
 protected:
  static void SetUpTestSuite() {
    CopyReference("export_reference");
    // Driven by a tracked workspace too (the same capture's: what is tested
    // is that another workspace's tracking reaches the avatar).
    exported_ = Headforge({"export", "--workspace", reference_.string(), "--texture-size", "128", "--bake-views", "8",
                           "--drive", TrackedTalkingStatic().string()});
  }
  static Result exported_;
};
Result ExportStage::exported_;

// The mesh avatar as the fixture's export baked it (texture 128, 8 views),
// on a core Mesh with its texture, unlit, for the mesh renderer.
struct BakedMeshAvatar {
  MeshAvatar avatar;
  Texture texture;
  Mesh mesh;  // its material points at `texture`: the struct stays where it was made
};
void BakeAsExported(const fs::path& ws, BakedMeshAvatar* baked) {
  FaceModel model;
  ASSERT_TRUE(FaceModel::Load(DefaultDataDir() + "/ict_facekit/ict_face_model.h5", &model).ok());
  MeshAvatarOptions options;
  options.texture_size = 128;
  options.bake_views = 8;
  NullProgress quiet;
  ASSERT_TRUE(BuildMeshAvatar(ws, model, options, &quiet, &baked->avatar).ok());
  baked->avatar.texture.convertTo(baked->texture.image, CV_32FC3, 1.0 / 255);
  baked->mesh.triangles = baked->avatar.triangles;
  baked->mesh.uvs = baked->avatar.texcoords;
  baked->mesh.uvs.row(1) = 1.0f - baked->avatar.texcoords.row(1).array();  // the renderer's v runs up
  Material material;
  material.texture = &baked->texture;
  material.lit = false;
  baked->mesh.materials = {material};
}

int CountVideoFrames(const fs::path& video) {
  const fs::path out = Scratch("ffprobe.txt");
  const std::string command = "ffprobe -v error -select_streams v:0 -count_frames -show_entries "
                              "stream=codec_name,nb_read_frames -of csv=p=0 '" + video.string() + "' > '" +
                              out.string() + "'";
  if (std::system(command.c_str()) != 0) return -1;
  const std::string text = Slurp(out);  // "h264,25"
  if (text.rfind("h264,", 0) != 0) return -2;
  return std::stoi(text.substr(5));
}

// Export killed without warning in the middle (the mesh avatar written into
// its staging folder, the rest not yet) leaves the earlier export whole; run
// again, it writes the same bytes as an export that was never stopped.
TEST_F(ExportStage, KilledMidExportRunsAgainToTheSameFiles) {
  ASSERT_EQ(exported_.code, 0) << exported_.err;
  const auto args = [](const fs::path& ws) {
    return std::vector<std::string>{"export", "--workspace", ws.string(), "--texture-size", "64", "--bake-views", "4",
                                    "--formats", "mesh", "gaussians", "weights", "videos"};
  };
  const fs::path whole = CopyOf(reference_, Scratch("export_whole")), killed = CopyOf(reference_, Scratch("export_killed"));
  const Result uninterrupted = Headforge(args(whole));
  ASSERT_EQ(uninterrupted.code, 0) << uninterrupted.err;
  const fs::path log = Scratch("export_killed.log");
  const pid_t pid = Spawn(args(killed), log, log);
  const fs::path staged = killed / ".staging" / "export" / "export" / "avatar_mesh.glb";
  int status = 0;
  const bool stopped = SignalWhen(pid, SIGKILL, [&] { return fs::exists(staged); }, std::chrono::seconds(120), &status);
  ASSERT_TRUE(stopped) << "export finished before it could be killed:\n" << Slurp(log);
  ASSERT_TRUE(WIFSIGNALED(status));
  const fs::path out = killed / "export";
  // The earlier export (the fixture's, copied with the workspace) is left whole.
  EXPECT_EQ(FileHash(out / "avatar_mesh.glb"), FileHash(reference_ / "export" / "avatar_mesh.glb"));
  const Result rerun = Headforge(args(killed));
  ASSERT_EQ(rerun.code, 0) << rerun.err;
  for (const char* file : {"avatar_mesh.glb", "gaussians.ply", "gaussians.glb", "weights/weights.safetensors"})
    EXPECT_EQ(FileHash(out / file), FileHash(whole / "export" / file)) << file;
}

// A disk that fills during an export (a file-size limit stands in for it):
// one clear error, the earlier export and everything else left as they
// were; with room again, the export completes.
TEST_F(ExportStage, AFullDiskDuringAnExportSaysSoAndKeepsTheEarlierExport) {
  ASSERT_EQ(exported_.code, 0) << exported_.err;
  const fs::path ws = CopyOf(reference_, Scratch("export_full_disk"));
  const std::vector<std::string> args = {"export", "--workspace", ws.string(), "--texture-size", "64",
                                         "--bake-views", "4", "--formats", "mesh", "weights"};
  const auto before = Snapshot(ws);
  ASSERT_TRUE(before.count("export/avatar_mesh.glb"));
  const Result full = HeadforgeWithFileLimit(args, 64);
  EXPECT_EQ(full.code, 1) << full.err;
  EXPECT_NE(full.err.find("ulimit -f, or a full disk"), std::string::npos) << full.err;
  EXPECT_EQ(ReasonLines(full.err).size(), 1u) << full.err;
  EXPECT_EQ(Snapshot(ws), before);
  const Result again = Headforge(args);
  ASSERT_EQ(again.code, 0) << again.err;
  EXPECT_TRUE(fs::exists(ws / "export" / "weights" / "weights.safetensors"));
}

// The Gaussians of the exported gaussians.ply whose centre lies, through a
// frame's camera, outside that frame's mask in every frame: what no mask
// shows the person at, which a viewer turning the avatar would show
// floating (below the chin, before training pruned them). As a fraction of
// all.
double UnseenFraction(const fs::path& ws) {
  GaussianCloud cloud;
  EXPECT_TRUE(ReadGaussianPly(ws / "export" / "gaussians.ply", &cloud).ok());
  CameraSet cameras;
  EXPECT_TRUE(CameraSet::Read(ws / "cameras_head.json", &cameras).ok());
  const size_t n = cloud.size();
  std::vector<bool> seen(n, false);
  for (const CameraView& view : cameras.views) {
    const CameraIntrinsics* in = cameras.FindCamera(view.camera);
    if (!view.registered || !in) continue;
    char name[32];
    std::snprintf(name, sizeof(name), "%06d.png", view.frame);
    const cv::Mat mask = cv::imread((ws / "masks" / view.camera / name).string(), cv::IMREAD_GRAYSCALE);
    EXPECT_FALSE(mask.empty()) << name;
    if (mask.empty()) continue;
    for (size_t i = 0; i < n; ++i) {
      const Eigen::Vector3d p =
          view.cam_from_world * Eigen::Vector3d(cloud.means[3 * i], cloud.means[3 * i + 1], cloud.means[3 * i + 2]);
      if (p.z() <= 0.01) continue;
      const int u = int(std::lround(in->fx * p.x() / p.z() + in->cx));
      const int v = int(std::lround((in->fy > 0 ? in->fy : in->fx) * p.y() / p.z() + in->cy));
      if (u >= 0 && v >= 0 && u < mask.cols && v < mask.rows && mask.at<uchar>(v, u) > 127) seen[i] = true;
    }
  }
  return n ? double(std::count(seen.begin(), seen.end(), false)) / n : 0.0;
}

// Training removes the Gaussians no training view shows over the person;
// the export (the neutral pose: no expression, frame 0's head pose) then
// holds almost none outside every frame's mask (a few cross the edge as the
// pose changes).
TEST_F(ExportStage, TheExportedGaussiansLieWhereTheMasksShowThePerson) {
  ASSERT_EQ(exported_.code, 0) << exported_.err;
  const double unseen = UnseenFraction(reference_);
  std::printf("exported Gaussians outside every frame's mask: %.2f %%\n", 100 * unseen);
  EXPECT_LT(unseen, 0.01);
}

// --formats blendshapes: the avatar as linear Gaussian blendshapes (a
// neutral state and one offset per expression for every Gaussian), fitted
// to its networks, then refined against the training frames. As fitted
// they score within 0.5 dB of the networks on the held-out frames (0.02 dB
// below them here); the refinement, judged by training views set aside,
// keeps a state those views score higher, and the held-out frames no worse;
// posing and drawing a view takes less time than the networks; the binary
// holds what its JSON lays out (and blendshapes.glb as morph targets,
// validated), render --model draws a frame with them close to the
// networks' drawing, and with every weight 0 the Gaussians sit where the
// exported neutral ones do (those are posed at frame 0's head pose, the
// blendshapes at the training views' mean).
TEST_F(ExportStage, BlendshapesPoseTheAvatarAsItsNetworksDo) {
  ASSERT_EQ(exported_.code, 0) << exported_.err;
  const fs::path ws = CopyOf(reference_, Scratch("blendshapes"));
  const Result r = Headforge({"export", "--workspace", ws.string(), "--formats", "blendshapes"});
  ASSERT_EQ(r.code, 0) << r.err;
  const fs::path dir = ws / "export" / "blendshapes";
  nlohmann::json layout;
  ASSERT_TRUE(ReadJson(dir / "blendshapes.json", &layout).ok());
  const size_t n = layout["gaussians"], k = layout["expressions"].size(), a = layout["attributes"].size();
  EXPECT_EQ(k, 53u);
  EXPECT_EQ(a, 13u);
  const auto& names = layout["expressions"];
  EXPECT_NE(std::find(names.begin(), names.end(), "jawOpen"), names.end());
  std::string bytes;
  ASSERT_TRUE(ReadFileToString(dir / "blendshapes.bin", &bytes).ok());
  ASSERT_EQ(bytes.size(), 4 * (n + n * a * (1 + k)));
  EXPECT_EQ(layout["binary"]["offsets"]["offset"].get<size_t>(), 4 * n * (1 + a));
  const nlohmann::json& held = layout["held_out"];
  const double network = held["psnr_masked_network"], fitted = held["psnr_masked_fitted"],
               linear = held["psnr_masked_blendshapes"];
  std::printf("held out over the head: blendshapes %.2f dB (as fitted %.2f dB), networks %.2f dB; %.1f against %.1f "
              "ms a view\n",
              linear, fitted, network, held["ms_blendshapes"].get<double>(), held["ms_network"].get<double>());
  EXPECT_EQ(held["views"], 25);
  EXPECT_GT(fitted, network - 0.5);
  EXPECT_GT(linear, fitted - 0.2);
  EXPECT_GT(network, 22.0);
  const nlohmann::json& refined = layout["refinement"];
  std::printf("refinement: %d steps, step %d kept, the %d views set aside %.2f -> %.2f dB\n",
              refined["steps"].get<int>(), refined["kept_step"].get<int>(), refined["validation_views"].get<int>(),
              refined["validation_psnr_masked_before"].get<double>(),
              refined["validation_psnr_masked_after"].get<double>());
  EXPECT_EQ(refined["steps"], 300);
  EXPECT_GT(refined["validation_views"].get<int>(), 0);
  EXPECT_GE(refined["validation_psnr_masked_after"].get<double>(), refined["validation_psnr_masked_before"].get<double>());
  EXPECT_EQ(refined["validation_curve"].size(), 7u);  // before, every 50 steps, the last
  // Half the Gaussians pruned by default, before the refinement.
  const nlohmann::json& pruning = layout["pruning"];
  std::printf("pruned to %d of %d Gaussians (%.1f%% of the light): held out %.2f dB before the refinement\n",
              pruning["gaussians_kept"].get<int>(), pruning["gaussians_fitted"].get<int>(),
              100 * pruning["light_kept"].get<double>(), held["psnr_masked_pruned"].get<double>());
  EXPECT_EQ(pruning["gaussians_kept"], n);
  EXPECT_EQ(n, size_t(std::lround(0.5 * pruning["gaussians_fitted"].get<double>())));
  // A fraction to prune outside [0, 1) is refused before anything is touched.
  const Result bad = Headforge({"export", "--workspace", ws.string(), "--formats", "blendshapes", "--blendshape-prune", "1"});
  EXPECT_EQ(bad.code, 2) << bad.err;
  EXPECT_NE(bad.err.find("0.5 removes half"), std::string::npos) << bad.err;
  EXPECT_TRUE(fs::exists(dir / "blendshapes.json"));
  EXPECT_LT(held["ms_blendshapes"].get<double>(), held["ms_network"].get<double>());

  GaussianCloud neutral;
  ASSERT_TRUE(ReadGaussianPly(reference_ / "export" / "gaussians.ply", &neutral).ok());
  ASSERT_EQ(neutral.size(), pruning["gaussians_fitted"].get<size_t>());
  const std::vector<int64_t> kept = pruning["kept"];
  ASSERT_EQ(kept.size(), n);
  EXPECT_TRUE(std::is_sorted(kept.begin(), kept.end()));
  EXPECT_LT(kept.back(), int64_t(neutral.size()));
  std::vector<float> values(n * a);
  std::memcpy(values.data(), bytes.data() + 4 * n, values.size() * sizeof(float));
  double squares = 0;
  for (size_t i = 0; i < n; ++i)
    for (size_t c = 0; c < 3; ++c)
      squares += std::pow(double(values[i * a + c]) - neutral.means[3 * size_t(kept[i]) + c], 2);
  const double rms_mm = 1000 * std::sqrt(squares / double(n));
  std::printf("neutral positions %.3f mm (RMS) from the exported neutral Gaussians\n", rms_mm);
  EXPECT_LT(rms_mm, 1.0);
  // render --model draws them by the model table's name or by their folder:
  // a held-out frame as the networks draw it.
  const fs::path renders = Scratch("blendshape_renders");
  for (const std::string& model : {std::string("gaussian-style"), std::string("gaussian-blendshapes"), dir.string()}) {
    const Result render = Headforge({"render", "--workspace", ws.string(), "--frames", "110", "--model", model,
                                     "--out", (renders / fs::path(model).filename()).string()});
    ASSERT_EQ(render.code, 0) << render.err;
  }
  const cv::Mat by_networks = cv::imread((renders / "gaussian-style" / "frame_000110.png").string());
  const cv::Mat by_blendshapes = cv::imread((renders / "gaussian-blendshapes" / "frame_000110.png").string());
  ASSERT_FALSE(by_networks.empty() || by_blendshapes.empty());
  const cv::Mat by_folder = cv::imread((renders / "blendshapes" / "frame_000110.png").string());
  ASSERT_FALSE(by_folder.empty());
  EXPECT_EQ(cv::norm(by_blendshapes, by_folder, cv::NORM_INF), 0);  // the name is the folder
  const double agreement = cv::PSNR(by_networks, by_blendshapes);
  std::printf("frame 110 drawn by the blendshapes against the networks: %.1f dB\n", agreement);
  EXPECT_GT(agreement, 36.0);  // 42.4 dB here refined (54.9 dB as fitted, the networks' own drawing)
  // A name the workspace has not made says what makes it; train refuses an exported model.
  const Result missing = Headforge({"render", "--workspace", ws.string(), "--model", "gan-avatar", "--frames", "110",
                                    "--out", (renders / "missing").string()});
  EXPECT_EQ(missing.code, 1) << missing.err;
  EXPECT_NE(missing.err.find("headforge train --workspace " + ws.string() + " --model gan-avatar"), std::string::npos)
      << missing.err;
  // status lists the models render can draw, trained and exported.
  const Result status = Headforge({"status", ws.string()});
  EXPECT_EQ(status.code, 0) << status.err;
  EXPECT_NE(status.out.find("gaussian-style        models/gaussian_style"), std::string::npos) << status.out;
  EXPECT_NE(status.out.find("gaussian-blendshapes  export/blendshapes"), std::string::npos) << status.out;
  EXPECT_EQ(status.out.find("gan-avatar"), std::string::npos) << status.out;
  const Result trained = Headforge({"train", "--workspace", ws.string(), "--model", "gaussian-blendshapes"});
  EXPECT_EQ(trained.code, 2) << trained.err;
  EXPECT_NE(trained.err.find("export --formats blendshapes"), std::string::npos) << trained.err;
  // Blendshapes whose binary lost its end are refused, saying what to do.
  std::filesystem::resize_file(dir / "blendshapes.bin", fs::file_size(dir / "blendshapes.bin") - 4);
  const Result cut = Headforge({"render", "--workspace", ws.string(), "--frames", "110", "--model", dir.string(),
                                "--out", (renders / "cut").string()});
  EXPECT_EQ(cut.code, 1) << cut.err;
  EXPECT_NE(cut.err.find("export them again"), std::string::npos) << cut.err;

  // The glTF asset: a morph target per expression, on the neutral Gaussians.
  EXPECT_TRUE(fs::exists(dir / "blendshapes.glb"));
#ifdef HEADFORGE_GLTF_VALIDATOR
  EXPECT_EQ(std::system((std::string("'") + HEADFORGE_NODE + "' '" + HEADFORGE_TEST_SOURCE_DIR +
                         "/scripts/validate_gltf.cjs' '" + (dir / "blendshapes.glb").string() + "' --validator '" +
                         HEADFORGE_GLTF_VALIDATOR + "' --extension-attributes KHR_gaussian_splatting")
                            .c_str()),
            0);
#endif
}

TEST_F(ExportStage, WritesEveryFormatAndEachReadsBack) {
  ASSERT_EQ(exported_.code, 0) << exported_.err;
  const fs::path out = reference_ / "export";
  for (const char* file : {"avatar_mesh.glb", "gaussians.ply", "gaussians.glb", "weights/weights.safetensors",
                           "weights/config.json", "videos/self_reenactment.mp4", "videos/orbit.mp4",
                           "viewer/index.html", "report.html", "export.json"})
    EXPECT_TRUE(fs::exists(out / file)) << file;
  // The face metrics: their record, measured or saying why not.
  nlohmann::json faces;
  ASSERT_TRUE(ReadJson(out / "face_metrics.json", &faces).ok());
  EXPECT_TRUE(faces.value("views", 0) == 25 || !faces.value("missing", std::string()).empty()) << faces;
  // H.264 videos: the 25 held-out frames, and a 72-step orbit.
  EXPECT_EQ(CountVideoFrames(out / "videos" / "self_reenactment.mp4"), 25);
  EXPECT_EQ(CountVideoFrames(out / "videos" / "orbit.mp4"), 72);
  EXPECT_EQ(CountVideoFrames(out / "videos" / "cross_reenactment.mp4"), 125);
  // The track stage's overlay, now H.264 too, among the videos.
  EXPECT_EQ(CountVideoFrames(out / "videos" / "tracking_overlay_cam0.mp4"), 125);
#ifdef HEADFORGE_GLTF_VALIDATOR
  const auto validate = [&](const fs::path& file, const std::string& extra) {
    return std::system((std::string("'") + HEADFORGE_NODE + "' '" + HEADFORGE_TEST_SOURCE_DIR +
                        "/scripts/validate_gltf.cjs' '" + file.string() + "' --validator '" + HEADFORGE_GLTF_VALIDATOR +
                        "' " + extra)
                           .c_str());
  };
  EXPECT_EQ(validate(out / "avatar_mesh.glb", ""), 0);
  EXPECT_EQ(validate(out / "gaussians.glb", "--extension-attributes KHR_gaussian_splatting"), 0);
#endif
#ifdef HEADFORGE_PYTHON3
  // A second reader of the weights: Python's json and struct, from the format's description.
  const fs::path script = Scratch("read_safetensors.py"), listing = Scratch("safetensors.txt");
  ASSERT_TRUE(WriteFileAtomic(script,
                              "import json, struct, sys\n"
                              "raw = open(sys.argv[1], 'rb').read()\n"
                              "n = struct.unpack('<Q', raw[:8])[0]\n"
                              "head = json.loads(raw[8:8 + n])\n"
                              "head.pop('__metadata__', None)\n"
                              "end = 0\n"
                              "for name, e in sorted(head.items(), key=lambda kv: kv[1]['data_offsets']):\n"
                              "    b, f = e['data_offsets']\n"
                              "    assert b == end, name\n"
                              "    count = 1\n"
                              "    for d in e['shape']: count *= d\n"
                              "    assert f - b == count * {'F32': 4, 'I64': 8}[e['dtype']], name\n"
                              "    end = f\n"
                              "    print(name, e['dtype'], 'x'.join(map(str, e['shape'])))\n"
                              "assert 8 + n + end == len(raw)\n")
                  .ok());
  ASSERT_EQ(std::system((std::string(HEADFORGE_PYTHON3) + " '" + script.string() + "' '" +
                         (out / "weights" / "weights.safetensors").string() + "' > '" + listing.string() + "'")
                            .c_str()),
            0);
  const std::string names = Slurp(listing);
  nlohmann::json config;
  ASSERT_TRUE(ReadJson(reference_ / kModelDir / "config.json", &config).ok());
  const std::string gaussians = std::to_string(config["gaussians"].get<int>());
  EXPECT_NE(names.find("gaussians.means F32 " + gaussians + "x3\n"), std::string::npos) << names;
  EXPECT_NE(names.find("gaussians.features F32 " + gaussians + "x32\n"), std::string::npos) << names;
  EXPECT_NE(names.find("model.latents"), std::string::npos) << names;
#endif
}

TEST_F(ExportStage, TheExportedWeightsRenderTheSameImages) {
  ASSERT_EQ(exported_.code, 0) << exported_.err;
  const fs::path a = Scratch("weights_a"), b = Scratch("weights_b");
  ASSERT_EQ(Headforge({"render", "--workspace", reference_.string(), "--frames", "3,110", "--out", a.string()}).code, 0);
  const Result r = Headforge({"render", "--workspace", reference_.string(), "--frames", "3,110", "--model",
                              (reference_ / "export" / "weights").string(), "--out", b.string()});
  ASSERT_EQ(r.code, 0) << r.err;
  for (const char* f : {"frame_000003.png", "frame_000110.png"})
    EXPECT_EQ(FileHash(a / f), FileHash(b / f)) << f;
}

// The mesh avatar redraws the simulator's frames: its animation at frame k
// through the capture's camera, with the baked texture, against frame k
// over the head mask where the mesh covers it.
TEST_F(ExportStage, TheBakedMeshAvatarRedrawsTheFrames) {
  ASSERT_EQ(exported_.code, 0) << exported_.err;
  BakedMeshAvatar baked;
  ASSERT_NO_FATAL_FAILURE(BakeAsExported(reference_, &baked));
  const MeshAvatar& avatar = baked.avatar;
  Mesh& mesh = baked.mesh;
  EXPECT_EQ(avatar.target_names.size(), 53u);
  EXPECT_EQ(avatar.times.size(), 125u);
  nlohmann::json cameras;
  ASSERT_TRUE(ReadJson(reference_ / "cameras_head.json", &cameras).ok());
  const nlohmann::json& lens = cameras["cameras"][0];
  for (int frame : {10, 60, 115}) {
    mesh.vertices = MeshAvatarVertices(avatar, frame);
    PinholeCamera camera;
    camera.fx = lens["fx"];
    camera.fy = lens["fy"];
    camera.cx = lens["cx"];
    camera.cy = lens["cy"];
    camera.width = lens["width"];
    camera.height = lens["height"];
    camera.cam_from_world = avatar.cam_from_world;  // head-pose cameras hold still
    RenderOutput drawn;
    RenderMeshes({&mesh}, camera, RenderOptions(), &drawn);
    char name[32];
    std::snprintf(name, sizeof(name), "%06d.png", frame);
    const cv::Mat image = cv::imread((reference_ / "frames" / "cam0" / name).string());
    const cv::Mat mask = cv::imread((reference_ / "masks" / "cam0" / name).string(), cv::IMREAD_GRAYSCALE);
    ASSERT_FALSE(image.empty());
    cv::Mat truth, covered;
    image.convertTo(truth, CV_32FC3, 1.0 / 255);
    cv::erode((mask > 128) & (drawn.coverage > 0.99), covered, cv::Mat(), cv::Point(-1, -1), 2);
    ASSERT_GT(cv::countNonZero(covered), 500) << frame;
    const double mse = cv::norm(drawn.color, truth, cv::NORM_L2SQR, covered) / (3.0 * cv::countNonZero(covered));
    // A flat texture of the frame's mean colour there, for scale.
    const cv::Scalar mean = cv::mean(truth, covered);
    cv::Mat flat(truth.size(), CV_32FC3, mean);
    const double mse_flat = cv::norm(flat, truth, cv::NORM_L2SQR, covered) / (3.0 * cv::countNonZero(covered));
    const double psnr = 10 * std::log10(1 / mse), psnr_flat = 10 * std::log10(1 / mse_flat);
    std::printf("mesh avatar at frame %d: %.2f dB over %d px of head (a flat colour: %.2f dB)\n", frame, psnr,
                cv::countNonZero(covered), psnr_flat);
    // Seen: 27.0, 25.3 and 22.8 dB (tracking's error grows toward the end).
    EXPECT_GT(psnr, 21.0) << frame;
    EXPECT_GT(psnr, psnr_flat + 6.0) << frame;
  }
}

// `headforge bench train --ladder`: each rung trained with the options
// given, its steps as named, a second call scoring the rungs it finds
// instead of training them again, and the rows in the report's table.
TEST_F(ExportStage, TheBenchLadderTrainsEachRungAndTheReportTablesThem) {
  ASSERT_EQ(exported_.code, 0) << exported_.err;
  const fs::path ws = CopyOf(reference_, Scratch("bench_ladder"));
  std::vector<std::string> args = {"bench", "train", "--workspace", ws.string(), "--ladder", "30,60", "--json"};
  for (const auto& a : TinyOptions()) args.push_back(a);
  const Result first = Headforge(args);
  ASSERT_EQ(first.code, 0) << first.err;
  const nlohmann::json rows = nlohmann::json::parse(first.out).at("variants");
  ASSERT_EQ(rows.size(), 2u);
  EXPECT_EQ(rows[0]["steps"], 30);
  EXPECT_EQ(rows[1]["steps"], 60);
  EXPECT_EQ(rows[1]["what"], "60 steps");
  for (const nlohmann::json& r : rows) {
    EXPECT_GT(r["seconds"].get<double>(), 0);
    EXPECT_GT(r["psnr_masked"].get<double>(), 10);
  }
  // The longer rung fits its training views better.
  EXPECT_GT(rows[1]["train_psnr_masked"].get<double>(), rows[0]["train_psnr_masked"].get<double>());
  const Result again = Headforge(args);
  ASSERT_EQ(again.code, 0) << again.err;
  EXPECT_EQ(nlohmann::json::parse(again.out).at("variants"), rows);
  EXPECT_EQ(again.err.find("train: gaussian-style"), std::string::npos) << again.err;  // nothing trained
  // A rung that is not one is refused before anything trains.
  const Result bad = Headforge({"bench", "train", "--workspace", ws.string(), "--ladder", "30,12x"});
  EXPECT_EQ(bad.code, 2);
  EXPECT_NE(bad.err.find("'12x' is not STEPS, STEPS/GAUSSIANS or a preset"), std::string::npos) << bad.err;
  const Result report = Headforge({"export", "--workspace", ws.string(), "--formats", "report"});
  ASSERT_EQ(report.code, 0) << report.err;
  const std::string html = Slurp(ws / "export" / "report.html");
  EXPECT_NE(html.find("<tr><td>60 steps</td><td>gaussian-style</td><td class=\"num\">60</td>"), std::string::npos);
}

// The calibration and tracking benches' results in the report: the
// workspace's bench_calibrate/ and bench_track/ files by default (rows in
// the layout `headforge bench calibrate|track` writes), a changed file runs
// export again, --bench-results names others, and a file that is not a
// bench's is said on the page.
TEST_F(ExportStage, TheReportPlotsTheCalibrationAndTrackingBenches) {
  ASSERT_EQ(exported_.code, 0) << exported_.err;
  const fs::path ws = CopyOf(reference_, Scratch("bench_results"));
  const nlohmann::json calibrate = {
      {"version", 1},
      {"bench", "calibrate"},
      {"settings",
       {{{"scene", "rig_8cam"}, {"setting", "baseline"}, {"ok", true}, {"seconds", 41.5}, {"registered", 24},
         {"frames", 24}, {"rotation_deg_median", 0.031}, {"rotation_deg_max", 0.07}, {"centre_mm_median", 0.52},
         {"focal_error", 0.0012}, {"aligned_rotation_deg_median", 0.61}},
        {{"scene", "rig_8cam"}, {"setting", "no COLMAP"}, {"ok", false}, {"seconds", 1.0}}}},
      {"subjects", nlohmann::json::array()}};
  const nlohmann::json track = {{"version", 1},
                                {"bench", "track"},
                                {"tracks",
                                 {{{"subject", "identity seed 3"}, {"points", "plain"}, {"ok", true}, {"seconds", 12.0},
                                   {"residual_px", 0.81}, {"rotation_deg", 1.72},
                                   {"blendshape_mae", {{"jawOpen", 0.043}}}}}}};
  ASSERT_TRUE(WriteJsonAtomic(ws / "bench_calibrate" / "results.json", calibrate, 1).ok());
  ASSERT_TRUE(WriteJsonAtomic(ws / "bench_track" / "results.json", track, 1).ok());
  // (--face-api "": the identity score, which this test does not read, left out.)
  const Result r = Headforge({"export", "--workspace", ws.string(), "--formats", "report", "--face-api", ""});
  ASSERT_EQ(r.code, 0) << r.err;
  std::string html = Slurp(ws / "export" / "report.html");
  for (const char* part : {"<canvas id=\"bench_calibrate\">", "<canvas id=\"bench_track\">",
                           "<tr><td>rig_8cam</td><td>baseline</td><td class=\"num\">42 s</td><td class=\"num\">24/24",
                           "<td class=\"num\">0.031 / 0.070°</td>", "<td>identity seed 3</td><td>plain</td>",
                           "<td class=\"num\">1.72°</td><td class=\"num\">0.043</td>"})
    EXPECT_NE(html.find(part), std::string::npos) << part;
  EXPECT_EQ(html.find("no COLMAP"), std::string::npos);  // a failed setting has no figures to plot
#ifdef HEADFORGE_BROWSER_CHECKS
  // Both charts drawn, no console error; the screenshot kept as an artefact.
  const fs::path shot = Artefact("report_benches.png");
  const std::string command = OpenPageCommand(ws / "export", "report.html", 1100, 900, shot, "--full-page 1");
  EXPECT_EQ(std::system(command.c_str()), 0) << command;
#endif
  // A bench run again changes its file, and export runs again.
  nlohmann::json again = track;
  again["tracks"][0]["rotation_deg"] = 2.5;
  ASSERT_TRUE(WriteJsonAtomic(ws / "bench_track" / "results.json", again, 1).ok());
  ASSERT_EQ(Headforge({"export", "--workspace", ws.string(), "--formats", "report", "--face-api", ""}).code, 0);
  html = Slurp(ws / "export" / "report.html");
  EXPECT_NE(html.find("<td class=\"num\">2.50°</td>"), std::string::npos);
  // Named files instead; one that no bench wrote is said.
  const Result named = Headforge({"export", "--workspace", ws.string(), "--formats", "report", "--face-api", "", "--bench-results",
                                  (ws / "bench_track" / "results.json").string(), (ws / "tracking.json").string()});
  ASSERT_EQ(named.code, 0) << named.err;
  html = Slurp(ws / "export" / "report.html");
  EXPECT_EQ(html.find("<canvas id=\"bench_calibrate\">"), std::string::npos);
  EXPECT_NE(html.find("<canvas id=\"bench_track\">"), std::string::npos);
  EXPECT_NE(html.find("tracking.json are not from headforge bench calibrate or track"), std::string::npos);
}

// report.html: every file it references (videos beside it) exists, and
// everything else is inlined.
TEST_F(ExportStage, TheReportReferencesOnlyFilesThatExist) {
  ASSERT_EQ(exported_.code, 0) << exported_.err;
  const fs::path out = reference_ / "export";
  const std::string html = Slurp(out / "report.html");
  ASSERT_NE(html.find("<h2>Evaluation</h2>"), std::string::npos);
  ASSERT_NE(html.find("new Chart("), std::string::npos);  // the charting library is inlined
  int inlined = 0, beside = 0;
  for (size_t at = html.find("src=\""); at != std::string::npos; at = html.find("src=\"", at + 5)) {
    const size_t end = html.find('"', at + 5);
    const std::string src = html.substr(at + 5, end - at - 5);
    if (src.rfind("data:", 0) == 0) {
      ++inlined;
    } else {
      ++beside;
      EXPECT_TRUE(fs::exists(out / src)) << src;
    }
  }
  EXPECT_GE(inlined, 6);  // capture thumbnails and held-out strips
  EXPECT_EQ(beside, 4);   // the videos: self-reenactment, orbit, cross-reenactment, the tracking overlay
  EXPECT_NE(html.find("<code>viewer/index.html</code>"), std::string::npos);
}

#ifdef HEADFORGE_BROWSER_CHECKS
// three.js in headless Chromium plays the mesh avatar exported from `ws`
// (texture 128, 8 views): its glTF camera, the animation set to each of
// `frames`, the baked texture; each picture must match core's mesh renderer
// drawing the same avatar at that frame through a pinhole with the glTF
// camera's field of view (glTF has no principal-point offset, so the pinhole
// is centred), and the first frame's picture must agree less with the last
// frame's drawing (the animation, not a still pose, was played).
void ExpectThreeJsPlaysTheMeshAvatar(const fs::path& ws, const std::vector<int>& frames) {
  BakedMeshAvatar baked;
  ASSERT_NO_FATAL_FAILURE(BakeAsExported(ws, &baked));
  const MeshAvatar& avatar = baked.avatar;
  Mesh& mesh = baked.mesh;
  PinholeCamera camera;
  camera.width = 320;
  camera.height = 320;
  camera.fy = camera.fx = 0.5 * camera.height / std::tan(0.5 * avatar.yfov);
  camera.cx = camera.cy = 0.5 * camera.width - 0.5;
  camera.cam_from_world = avatar.cam_from_world;
  std::map<int, cv::Mat> shots, drawings;
  std::map<int, double> psnrs;
  const auto psnr_of = [](const cv::Mat& a, const cv::Mat& b, const cv::Mat& mask) {
    const double mse = cv::norm(a, b, cv::NORM_L2SQR, mask) / (3.0 * cv::countNonZero(mask));
    return 10 * std::log10(255.0 * 255.0 / std::max(mse, 1e-9));
  };
  cv::Mat inside;
  for (int frame : frames) {
    const fs::path shot = Scratch("three_" + std::to_string(frame) + ".png");
    const std::string command = std::string("'") + HEADFORGE_NODE + "' '" + HEADFORGE_TEST_SOURCE_DIR +
                                "/scripts/web/screenshot.cjs' --page mesh_frame.html --file '" +
                                (ws / "export" / "avatar_mesh.glb").string() + "' --query frame=" +
                                std::to_string(frame) + " --width 320 --height 320 --out '" + shot.string() +
                                "' --chromium '" + HEADFORGE_CHROMIUM + "'";
    ASSERT_EQ(std::system(command.c_str()), 0) << command;
    const cv::Mat three = cv::imread(shot.string());
    ASSERT_EQ(three.size(), cv::Size(320, 320));
    mesh.vertices = MeshAvatarVertices(avatar, frame);
    RenderOutput drawn;
    RenderMeshes({&mesh}, camera, RenderOptions(), &drawn);
    cv::Mat ours;
    drawn.color.convertTo(ours, CV_8UC3, 255, 0.5);
    cv::erode(drawn.coverage > 0.999, inside, cv::Mat(), cv::Point(-1, -1), 2);
    ASSERT_GT(cv::countNonZero(inside), 5000) << frame;
    psnrs[frame] = psnr_of(ours, three, inside);
    std::printf("three.js against the mesh renderer at frame %d of %s: %.2f dB over %d px\n", frame,
                ws.filename().c_str(), psnrs[frame], cv::countNonZero(inside));
    EXPECT_GE(psnrs[frame], 30.0) << frame;
    shots[frame] = three;
    drawings[frame] = ours;
  }
  const int first = frames.front(), last = frames.back();
  const double crossed = psnr_of(drawings[last], shots[first], inside);
  std::printf("three.js at frame %d against the mesh renderer at frame %d: %.2f dB\n", first, last, crossed);
  EXPECT_LT(crossed, std::min(psnrs[first], psnrs[last]) - 3.0);
}

TEST_F(ExportStage, ThreeJsPlaysTheMeshAvatarAsTheMeshRendererDrawsIt) {
  ASSERT_EQ(exported_.code, 0) << exported_.err;
  ExpectThreeJsPlaysTheMeshAvatar(reference_, {20, 90});
}

// The same on a real capture: the GRID clip bbaf2n's tracked workspace
// (track_test's), the mesh avatar exported alone, no model trained.
TEST(GridExport, ThreeJsPlaysTheMeshAvatarAsTheMeshRendererDrawsIt) {
  const fs::path grid = fs::path(HEADFORGE_TEST_SHARED_DATA) / "video" / "grid" / "bbaf2n.mpg";
  const fs::path ws = CopyOf(SharedRun("grid_bbaf2n", {grid.string()}), Scratch("grid_bbaf2n"));
  const Result e = Headforge({"export", "--workspace", ws.string(), "--formats", "mesh", "--texture-size", "128",
                              "--bake-views", "8"});
  ASSERT_EQ(e.code, 0) << e.err;
  ExpectThreeJsPlaysTheMeshAvatar(ws, {10, 45});
}

// What PlayCanvas's picture of one frame's Gaussians is compared with:
// `headforge render` of that frame at `size` pixels over a black background,
// the head's mask (eroded) where it is compared, and splat_view.html's query
// for the frame's camera in the head frame (its view times the tracked head
// motion).
struct SplatViewCheck {
  cv::Mat ours, head;
  std::string query;
  int size = 0;
};
void PrepareSplatView(const fs::path& ws, int frame, int size, SplatViewCheck* check) {
  const fs::path ours = Scratch("splat_view_ours_" + std::to_string(frame));
  const Result r = Headforge({"render", "--workspace", ws.string(), "--frames", std::to_string(frame), "--background",
                              "0", "--resolution", std::to_string(size), "--out", ours.string()});
  ASSERT_EQ(r.code, 0) << r.err;
  nlohmann::json cameras, tracking;
  ASSERT_TRUE(ReadJson(ws / "cameras_head.json", &cameras).ok());
  ASSERT_TRUE(ReadJson(ws / "tracking.json", &tracking).ok());
  Eigen::Isometry3d view = Eigen::Isometry3d::Identity(), motion = Eigen::Isometry3d::Identity();
  for (const auto& v : cameras["views"])
    if (v["frame"] == frame) view = PoseFromJson(v["cam_from_world"]);
  for (const auto& f : tracking["frames"])
    if (f["frame"] == frame) motion = PoseFromJson(f["head_motion"]);
  const Eigen::Isometry3d pose = view * motion;
  const nlohmann::json& lens = cameras["cameras"][0];
  const double scale = double(size) / std::max(lens["width"].get<int>(), lens["height"].get<int>());
  char query[2048];
  int at = std::snprintf(query, sizeof(query), "fx=%.9g&fy=%.9g&cx=%.9g&cy=%.9g&pose=",
                         lens["fx"].get<double>() * scale, lens["fy"].get<double>() * scale,
                         (lens["cx"].get<double>() + 0.5) * scale - 0.5, (lens["cy"].get<double>() + 0.5) * scale - 0.5);
  for (int i = 0; i < 16; ++i)
    at += std::snprintf(query + at, sizeof(query) - size_t(at), "%s%.12g", i ? "," : "", pose.matrix()(i / 4, i % 4));
  char name[32];
  std::snprintf(name, sizeof(name), "frame_%06d.png", frame);
  check->ours = cv::imread((ours / name).string());
  ASSERT_FALSE(check->ours.empty());
  std::snprintf(name, sizeof(name), "%06d.png", frame);
  cv::Mat mask = cv::imread((ws / "masks" / "cam0" / name).string(), cv::IMREAD_GRAYSCALE);
  cv::resize(mask, mask, check->ours.size(), 0, 0, cv::INTER_AREA);
  cv::erode(mask > 128, check->head, cv::Mat(), cv::Point(-1, -1), 1);
  ASSERT_GT(cv::countNonZero(check->head), 500);
  check->query = query;
  check->size = size;
}
// PlayCanvas's picture of `file` (.glb, .ply or .compressed.ply) through
// the check's camera, against HeadForge's: PSNR over the head (-1 when the
// page did not draw).
double PlayCanvasPsnr(const SplatViewCheck& check, const fs::path& file) {
  const fs::path shot = Scratch("playcanvas_" + file.filename().string() + ".png");
  const std::string command = std::string("'") + HEADFORGE_NODE + "' '" + HEADFORGE_TEST_SOURCE_DIR +
                              "/scripts/web/screenshot.cjs' --page splat_view.html --file '" + file.string() +
                              "' --query '" + check.query + "' --width " + std::to_string(check.size) + " --height " +
                              std::to_string(check.size) + " --out '" + shot.string() + "' --chromium '" +
                              HEADFORGE_CHROMIUM + "'";
  if (std::system(command.c_str()) != 0) return -1;
  const cv::Mat theirs = cv::imread(shot.string());
  if (theirs.size() != check.ours.size()) return -1;
  const double mse = cv::norm(theirs, check.ours, cv::NORM_L2SQR, check.head) / (3.0 * cv::countNonZero(check.head));
  const double psnr = 10 * std::log10(255.0 * 255.0 / std::max(mse, 1e-9));
  std::printf("PlayCanvas (%s) against headforge render at %d px: %.2f dB over %d px of head\n",
              file.filename().c_str(), check.size, psnr, cv::countNonZero(check.head));
  return psnr;
}

// PlayCanvas, which implements KHR_gaussian_splatting and reads 3D Gaussian
// Splatting's PLY, draws the exported Gaussians of frame 0 through frame 0's
// camera as `headforge render` does.
TEST_F(ExportStage, PlayCanvasDrawsTheGaussianGlbAsHeadForgeRendersIt) {
  ASSERT_EQ(exported_.code, 0) << exported_.err;
  const fs::path ws = CopyOf(reference_, Scratch("playcanvas"));
  const Result e = Headforge({"export", "--workspace", ws.string(), "--formats", "gaussians", "--splat-frame", "0"});
  ASSERT_EQ(e.code, 0) << e.err;
  SplatViewCheck check;
  ASSERT_NO_FATAL_FAILURE(PrepareSplatView(ws, 0, 128, &check));
  // The glTF, and the PLY the same engine reads as 3D Gaussian Splatting's layout.
  for (const char* file : {"gaussians.glb", "gaussians.ply"})
    EXPECT_GE(PlayCanvasPsnr(check, ws / "export" / file), 30.0) << file;
}

// report.html opens in headless Chromium: no console error, no request for a
// missing file, the charts drawn (window.done is set after them). The
// screenshot stays in the build tree as the test's artefact.
TEST_F(ExportStage, TheReportOpensInChromiumWithoutErrors) {
  ASSERT_EQ(exported_.code, 0) << exported_.err;
  const fs::path shot = Artefact("report.png");
  const std::string command = OpenPageCommand(reference_ / "export", "report.html", 1100, 900, shot, "--full-page 1");
  ASSERT_EQ(std::system(command.c_str()), 0) << command;
  const cv::Mat page = cv::imread(shot.string());
  ASSERT_FALSE(page.empty());
  EXPECT_GT(page.rows, 2000);  // every section laid out
}

// viewer/index.html, a file opened from disk, shows both avatars: no console
// error, and the page's left and right halves hold a head each (pixels away
// from the background's colour), from the front and, opened with ?yaw=180,
// from behind (another picture).
TEST_F(ExportStage, TheViewerPageShowsBothAvatars) {
  ASSERT_EQ(exported_.code, 0) << exported_.err;
  std::vector<cv::Mat> pages;
  for (const std::string query : {"", "--query yaw=180"}) {
    const fs::path shot = Artefact(query.empty() ? "viewer.png" : "viewer_back.png");
    const std::string command = OpenPageCommand(reference_ / "export" / "viewer", "index.html", 640, 400, shot, query);
    ASSERT_EQ(std::system(command.c_str()), 0) << command;
    const cv::Mat page = cv::imread(shot.string());
    ASSERT_EQ(page.size(), cv::Size(640, 400));
    const cv::Vec3b background = page.at<cv::Vec3b>(390, 5);
    for (const cv::Rect half : {cv::Rect(0, 40, 320, 360), cv::Rect(320, 40, 320, 360)}) {
      int head = 0;
      for (int y = half.y; y < half.br().y; ++y)
        for (int x = half.x; x < half.br().x; ++x)
          head += cv::norm(cv::Vec3i(page.at<cv::Vec3b>(y, x)) - cv::Vec3i(background)) > 40 ? 1 : 0;
      EXPECT_GT(head, 5000) << "x from " << half.x << " " << query;
    }
    pages.push_back(page);
  }
  // The back of the head is not the face: the two pictures differ.
  cv::Mat diff;
  cv::absdiff(pages[0], pages[1], diff);
  EXPECT_GT(cv::mean(diff)[0] + cv::mean(diff)[1] + cv::mean(diff)[2], 3.0);
}
#endif

#ifdef HEADFORGE_SPLAT_TRANSFORM
// A baked clip (--frames, SPZ): splat-transform reads frame 80's file back
// to frame 80's Gaussians, in order, within SPZ's quantisation (positions
// 1/4096 m, colour and opacity 8 bits, log scales 1/16, rotations 10 bits
// a component); PlayCanvas draws what it read through frame 80's camera as
// `headforge render` draws frame 80; the viewer page holds the clip's two
// frames and opens with the second shown.
TEST_F(ExportStage, TheBakedClipHoldsEachFrameAndTheViewerPlaysIt) {
  ASSERT_EQ(exported_.code, 0) << exported_.err;
  const fs::path ws = CopyOf(reference_, Scratch("clip"));
  const Result e = Headforge({"export", "--workspace", ws.string(), "--formats", "viewer", "--frames", "0-80:80"});
  ASSERT_EQ(e.code, 0) << e.err;
  nlohmann::json clip;
  ASSERT_TRUE(ReadJson(ws / "export" / "clip" / "clip.json", &clip).ok());
  EXPECT_EQ(clip["frames"], nlohmann::json({0, 80}));
  EXPECT_EQ(clip["format"], "spz");
  EXPECT_NEAR(clip["times_s"][1].get<double>(), 80 / clip["fps"].get<double>(), 1e-6);
  const fs::path back = Scratch("clip_80.ply");
  const std::string convert = std::string("'") + HEADFORGE_SPLAT_TRANSFORM + "' -q -w '" +
                              (ws / "export" / "clip" / "frame_000080.spz").string() + "' '" + back.string() + "'";
  ASSERT_EQ(std::system(convert.c_str()), 0) << convert;
  GaussianCloud read;
  ASSERT_TRUE(ReadGaussianPly(back, &read).ok());
  AvatarSplats posed;
  ASSERT_TRUE(PoseAvatarSplats(ws, ws / kModelDir, DefaultDataDir() + "/ict_facekit/ict_face_model.h5", 80, &posed).ok());
  const GaussianCloud truth = CloudFromSplats(posed);
  ASSERT_EQ(read.size(), truth.size());
  const auto sigmoid = [](float x) { return 1 / (1 + std::exp(-double(x))); };
  double position = 0, colour = 0, opacity = 0, scale = 0, turn = 0;
  for (size_t i = 0; i < truth.size(); ++i) {
    double dot = 0;
    for (int c = 0; c < 4; ++c) dot += read.rotations[4 * i + c] * truth.rotations[4 * i + c];
    turn = std::max(turn, 1 - std::abs(dot));
    opacity = std::max(opacity, std::abs(sigmoid(read.opacities[i]) - sigmoid(truth.opacities[i])));
    for (int c = 0; c < 3; ++c) {
      position = std::max(position, double(std::abs(read.means[3 * i + c] - truth.means[3 * i + c])));
      colour = std::max(colour, 0.2820948 * std::abs(read.sh_dc[3 * i + c] - truth.sh_dc[3 * i + c]));
      if (truth.log_scales[3 * i + c] > -10 && truth.log_scales[3 * i + c] < 5.9)  // SPZ's range
        scale = std::max(scale, double(std::abs(read.log_scales[3 * i + c] - truth.log_scales[3 * i + c])));
    }
  }
  std::printf("frame 80 read back from SPZ, largest errors: position %.2g m, colour %.2g, opacity %.2g, log scale "
              "%.2g, rotation 1-|dot| %.2g\n", position, colour, opacity, scale, turn);
  EXPECT_LE(position, 1.3e-4);
  EXPECT_LE(colour, 0.004);
  EXPECT_LE(opacity, 0.003);
  EXPECT_LE(scale, 0.035);
  EXPECT_LE(turn, 1e-3);
  // Not frame 0's Gaussians: the expression moved some of them.
  AvatarSplats first;
  ASSERT_TRUE(PoseAvatarSplats(ws, ws / kModelDir, DefaultDataDir() + "/ict_facekit/ict_face_model.h5", 0, &first).ok());
  double moved = 0;
  for (size_t i = 0; i < first.means.size(); ++i) moved = std::max(moved, double(std::abs(first.means[i] - posed.means[i])));
  EXPECT_GT(moved, 10 * position);
#ifdef HEADFORGE_BROWSER_CHECKS
  SplatViewCheck check;
  ASSERT_NO_FATAL_FAILURE(PrepareSplatView(ws, 80, 128, &check));
  EXPECT_GE(PlayCanvasPsnr(check, back), 30.0);
  // The page: both frames inlined, opened with the second held.
  const std::string page = Slurp(ws / "export" / "viewer" / "index.html");
  size_t blocks = 0;
  for (size_t at = page.find("<script id=\"clip"); at != std::string::npos; at = page.find("<script id=\"clip", at + 1))
    ++blocks;
  EXPECT_EQ(blocks, 2u);
  const fs::path shot = Artefact("viewer_clip.png");
  const std::string command = OpenPageCommand(ws / "export" / "viewer", "index.html", 320, 320, shot, "--query clip=1");
  ASSERT_EQ(std::system(command.c_str()), 0) << command;
#endif
}
#endif

TEST(ExportBadInput, AnUntrainedWorkspaceExportsTheMeshAndTheReportAlone) {
  const fs::path ws = CopyOf(TrackedTalkingStatic(), Scratch("untrained"));
  const Result all = Headforge({"export", "--workspace", ws.string(), "--texture-size", "64"});
  EXPECT_EQ(all.code, 1);
  EXPECT_NE(all.err.find("no trained avatar"), std::string::npos) << all.err;
  EXPECT_NE(all.err.find("run headforge train first, or export --formats mesh report alone"), std::string::npos)
      << all.err;
  EXPECT_FALSE(fs::exists(ws / "export"));
  const Result some = Headforge({"export", "--workspace", ws.string(), "--formats", "mesh,report", "--texture-size", "64"});
  ASSERT_EQ(some.code, 0) << some.err;
  EXPECT_TRUE(fs::exists(ws / "export" / "avatar_mesh.glb"));
  const std::string html = Slurp(ws / "export" / "report.html");
  EXPECT_NE(html.find("no trained model"), std::string::npos);
  EXPECT_EQ(html.find("<h2>Evaluation</h2>"), std::string::npos);
  const Result bogus = Headforge({"export", "--workspace", ws.string(), "--formats", "mesh,glb"});
  EXPECT_EQ(bogus.code, 2) << bogus.err;
  EXPECT_NE(bogus.err.find("unknown format 'glb'"), std::string::npos) << bogus.err;

  // What the export inlines from outside the workspace (here Chart.js) is
  // part of its fingerprint: another version of it makes the export run again.
  const fs::path chart = Scratch("untrained_chart.js");
  ASSERT_TRUE(WriteFileAtomic(chart, "/* chart, first version */").ok());
  const std::vector<std::string> report = {"export", "--workspace", ws.string(), "--formats", "report", "--chart-js",
                                           chart.string()};
  ASSERT_EQ(Headforge(report).code, 0);
  const Result same = Headforge(report);
  ASSERT_EQ(same.code, 0) << same.err;
  EXPECT_NE(same.err.find("export: up to date"), std::string::npos) << same.err;
  ASSERT_TRUE(WriteFileAtomic(chart, "/* chart, second version */").ok());
  const Result upgraded = Headforge(report);
  ASSERT_EQ(upgraded.code, 0) << upgraded.err;
  EXPECT_EQ(upgraded.err.find("up to date"), std::string::npos) << upgraded.err;
  EXPECT_NE(Slurp(ws / "export" / "report.html").find("chart, second version"), std::string::npos);
}

// Edits `file` (JSON) of `ws` in place.

}  // namespace
}  // namespace headforge
