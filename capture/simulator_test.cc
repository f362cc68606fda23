// The simulator against its own ground truth: landmarks, depth, masks,
// determinism, and every effect switched by the scene's list alone.
#include "capture/simulator.h"

#include <gtest/gtest.h>

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/videoio.hpp>

#include "capture/test_util.h"
#include "core/json_io.h"

namespace headforge {
namespace {

const char* kBaseScene = R"(
name = "test"
duration = 0.2
fps = 25
seed = 4
[subject]
identity = "random"
identity_seed = 3
[appearance]
texture_size = 256
[background]
type = "backdrop"
distance = 0.5
[camera]
rig = "static"
position = [0.05, 0.03, 0.6]
[camera.intrinsics]
width = 256
height = 256
focal = 560.0
[head]
yaw = { type = "sine", amplitude = 10.0, period = 1.0 }
[expressions]
jawOpen = { type = "keys", times = [0.0, 0.2], values = [0.0, 0.8] }
)";

class SimulatorTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    model_ = new FaceModel();
    const Status s = FaceModel::Load(
        (headforge::testing::SharedData() / "ict_facekit" / "ict_face_model.h5").string(), model_);
    ASSERT_TRUE(s.ok()) << s.message();
  }
  static void TearDownTestSuite() { delete model_; }

  // The base scene with root keys (`effects = [...]`, default none), extra
  // tables, and extra keys for its [appearance] table.
  static std::unique_ptr<Simulator> Make(const std::string& root = "effects = []", const std::string& extra_tables = "",
                                         const std::string& appearance = "") {
    std::string text = kBaseScene;
    text.insert(text.find("[appearance]\n") + 13, appearance + "\n");
    // Root keys must precede the first table.
    text.insert(text.find("[subject]"), root + "\n");
    text += "\n" + extra_tables + "\n";
    Scene scene;
    const Status parsed = ParseScene(text, "test.toml", &scene);
    EXPECT_TRUE(parsed.ok()) << parsed.message();
    std::unique_ptr<Simulator> sim;
    const Status created = Simulator::Create(scene, *model_, 2, &sim);
    EXPECT_TRUE(created.ok()) << created.message();
    return sim;
  }

  static FaceModel* model_;
};
FaceModel* SimulatorTest::model_ = nullptr;

// The UV of a vertex (from any triangle corner naming it).
Eigen::Vector2f VertexUv(const FaceModel& model, int vertex) {
  for (int t = 0; t < model.num_triangles(); ++t)
    for (int k = 0; k < 3; ++k)
      if (model.triangles()(k, t) == vertex) return model.uv_coords().col(model.uv_triangles()(k, t));
  ADD_FAILURE() << "vertex " << vertex << " in no triangle";
  return Eigen::Vector2f::Zero();
}

// True when the 3x3 pixels around `p` all show the face region of the head
// (not the eyeballs, the mouth interior or the background) on one continuous
// surface (depths within 4 mm: no lip or eyelid edge in between).
bool OnFaceSurface(const RenderOutput& r, cv::Point p, int face_triangles) {
  float near = 1e9f, far = -1e9f;
  for (int dy = -1; dy <= 1; ++dy)
    for (int dx = -1; dx <= 1; ++dx) {
      const cv::Point q(p.x + dx, p.y + dy);
      if (q.x < 0 || q.y < 0 || q.x >= r.triangle.cols || q.y >= r.triangle.rows) return false;
      const int id = r.triangle.at<int>(q);
      if (id < 0 || (id >> 24) != 0 || (id & 0xffffff) >= face_triangles) return false;
      near = std::min(near, r.depth.at<float>(q));
      far = std::max(far, r.depth.at<float>(q));
    }
  return far - near < 0.004f;
}

// Where the rendered face surface carries `uv`, to a fraction of a pixel: the
// nearest pixel centre, refined by the local UV gradient (UVs are linear in
// the image within a triangle's perspective-correct interpolation).
bool LocateUv(const RenderOutput& r, const Eigen::Vector2f& uv, int face_triangles, Eigen::Vector2d* where) {
  double best = 1e9;
  cv::Point best_px(-1, -1);
  for (int y = 1; y < r.uv.rows - 1; ++y)
    for (int x = 1; x < r.uv.cols - 1; ++x) {
      const int id = r.triangle.at<int>(y, x);
      if (id < 0 || (id >> 24) != 0 || (id & 0xffffff) >= face_triangles) continue;
      const cv::Vec2f p = r.uv.at<cv::Vec2f>(y, x);
      const double d = std::hypot(p[0] - uv.x(), p[1] - uv.y());
      if (d < best) {
        best = d;
        best_px = {x, y};
      }
    }
  if (best_px.x < 0 || !OnFaceSurface(r, best_px, face_triangles)) return false;
  const auto at = [&](int dx, int dy) {
    const cv::Vec2f p = r.uv.at<cv::Vec2f>(best_px.y + dy, best_px.x + dx);
    return Eigen::Vector2d(p[0], p[1]);
  };
  Eigen::Matrix2d j;
  j.col(0) = (at(1, 0) - at(-1, 0)) / 2;
  j.col(1) = (at(0, 1) - at(0, -1)) / 2;
  const Eigen::Vector2d delta = j.inverse() * (uv.cast<double>() - at(0, 0));
  *where = Eigen::Vector2d(best_px.x, best_px.y) + delta;
  return delta.norm() < 1.0;
}

TEST_F(SimulatorTest, ProjectedLandmarksCoincideWithTheRenderedVertices) {
  const auto sim = Make();
  const int face_triangles = model_->FindRegion("face")->last_triangle + 1;
  for (int frame : {0, 3}) {
    const SimulatedView view = sim->RenderView(frame, 0);
    int checked = 0;
    for (int i = 17; i < 68; ++i) {  // the jaw contour sits on silhouettes; inner points are stable
      if (!view.visible[i]) continue;
      Eigen::Vector2d rendered;
      // Eye corners and inner lips sit on eyelid and lip edges: no continuous
      // surface around them to refine the position with, so they are left out.
      if (!LocateUv(view.render, VertexUv(*model_, model_->landmarks_ibug68()[i]), face_triangles, &rendered))
        continue;
      EXPECT_LT((rendered - view.landmarks[i]).norm(), 0.5) << "landmark " << i << " frame " << frame;
      ++checked;
    }
    EXPECT_GE(checked, 25) << "frame " << frame;
  }
}

TEST_F(SimulatorTest, RenderedDepthAtALandmarkPixelMatchesItsDepth) {
  const auto sim = Make();
  const SimulatedView view = sim->RenderView(2, 0);
  const int face_triangles = model_->FindRegion("face")->last_triangle + 1;
  int checked = 0;
  for (int i = 17; i < 68; ++i) {
    if (!view.visible[i]) continue;
    const cv::Point p(static_cast<int>(std::lround(view.landmarks[i].x())), static_cast<int>(std::lround(view.landmarks[i].y())));
    if (!OnFaceSurface(view.render, p, face_triangles)) continue;  // at an eyelid or lip edge
    // Within half a pixel of a slanted surface: a few millimetres at most.
    EXPECT_NEAR(view.render.depth.at<float>(p), view.depth[i], 0.003) << "landmark " << i;
    ++checked;
  }
  EXPECT_GE(checked, 25);
  // The jaw landmarks are in front of the backdrop and behind the nose tip.
  EXPECT_GT(view.depth[8], view.depth[30]);
}

TEST_F(SimulatorTest, MaskMatchesTheRenderedCoverage) {
  const auto sim = Make();
  const SimulatedView view = sim->RenderView(1, 0);
  EXPECT_EQ(cv::countNonZero(view.mask != (view.render.coverage > 0.5f)), 0);
  // And with the part labels at pixel centres, but for antialiased edges.
  const cv::Mat head = (view.render.part == kPartFace) | (view.render.part == kPartHair);
  const double disagree = cv::countNonZero(head != view.mask);
  EXPECT_LT(disagree, 0.02 * cv::countNonZero(view.mask));
  EXPECT_GT(cv::countNonZero(view.mask), 0.1 * view.mask.total());
  EXPECT_EQ(view.mask.at<uint8_t>(0, 0), 0);
}

TEST_F(SimulatorTest, ASceneWithoutEffectsIsDeterministicForASeed) {
  const SimulatedView a = Make()->RenderView(3, 0);
  const SimulatedView b = Make()->RenderView(3, 0);
  EXPECT_EQ(cv::norm(a.image, b.image, cv::NORM_INF), 0.0);
  EXPECT_EQ(cv::norm(a.mask, b.mask, cv::NORM_INF), 0.0);
  // Another appearance seed gives another subject texture.
  const SimulatedView c = Make("effects = []", "", "seed = 99")->RenderView(3, 0);
  EXPECT_GT(cv::norm(a.image, c.image, cv::NORM_L1), 0.0);
}

// Parameters that make every effect visible on frame 1.
const char* kEffectParams = R"(
[effect.lighting]
ambient = 0.3
[effect.motion_blur]
samples = 3
[effect.rolling_shutter]
bands = 4
[effect.occlusion]
t_start = 0.0
t_end = 0.2
x0 = -0.05
x1 = 0.05
[effect.lens_distortion]
k1 = -0.25
[effect.defocus_blur]
strength = 12.0
[effect.exposure_drift]
amplitude = 0.5
[effect.white_balance_drift]
amplitude = 0.2
[effect.sensor_noise]
sigma = 4.0
)";

TEST_F(SimulatorTest, EachEffectChangesTheOutputOnlyWhenTheSceneListsIt) {
  const SimulatedView plain = Make()->RenderView(1, 0);
  // Parameters alone switch nothing on.
  const SimulatedView with_params = Make("effects = []", kEffectParams)->RenderView(1, 0);
  EXPECT_EQ(cv::norm(plain.image, with_params.image, cv::NORM_INF), 0.0);
  for (const auto& effect : KnownEffects()) {
    if (effect == "video_compression") continue;  // acts on the written video: next test
    const SimulatedView view = Make("effects = [\"" + effect + "\"]", kEffectParams)->RenderView(1, 0);
    const double change = cv::norm(plain.image, view.image, cv::NORM_L1) / plain.image.total();
    EXPECT_GT(change, 0.5) << effect << " left the image unchanged";
  }
}

TEST_F(SimulatorTest, CompressionWritesAVideoAndTheTruthRecordsTheEffects) {
  const fs::path dir = headforge::testing::ScratchDir();
  const auto sim = Make("effects = [\"video_compression\", \"sensor_noise\"]", "[effect.video_compression]\ncrf = 30\n");
  NullProgress progress;
  ASSERT_TRUE(WriteSimulation(*sim, dir, "", 0, &progress).ok());
  EXPECT_TRUE(fs::exists(dir / "cam0.mp4"));
  EXPECT_FALSE(fs::exists(dir / "cam0"));
  cv::VideoCapture video((dir / "cam0.mp4").string(), cv::CAP_FFMPEG);
  cv::Mat first;
  ASSERT_TRUE(video.read(first));
  const SimulatedView view = sim->RenderView(0, 0);
  ASSERT_EQ(first.size(), view.image.size());
  const double psnr = cv::PSNR(first, view.image);
  EXPECT_GT(psnr, 25.0);
  EXPECT_LT(psnr, 60.0);  // lossy: not the PNG frame
  nlohmann::json truth;
  ASSERT_TRUE(ReadJson(dir / "ground_truth.json", &truth).ok());
  ASSERT_EQ(truth["effects"].size(), 2u);
  EXPECT_EQ(truth["effects"][0]["name"], "sensor_noise");
  EXPECT_EQ(truth["effects"][1]["name"], "video_compression");
  EXPECT_EQ(truth["effects"][1]["params"]["crf"], 30.0);
  EXPECT_EQ(truth["frames"].size(), 5u);
  EXPECT_EQ(truth["frames"][4]["views"]["cam0"]["landmarks"].size(), 68u);
  EXPECT_NEAR(truth["frames"][4]["expression"]["jawOpen"].get<double>(), sim->StateAt(0.16).expression[model_->ExpressionIndex("jawOpen")], 1e-5);
}

TEST_F(SimulatorTest, RigCamerasLookAtTheTargetFromTheirArc) {
  Scene scene;
  ASSERT_TRUE(ParseScene(std::string(kBaseScene).replace(std::string(kBaseScene).find("rig = \"static\""), 14,
                                                         "rig = \"rig\"\ncount = 5\narc = 120.0\nradius = 0.7"),
                         "rig.toml", &scene)
                  .ok());
  std::unique_ptr<Simulator> rig;
  ASSERT_TRUE(Simulator::Create(scene, *model_, 2, &rig).ok());
  ASSERT_EQ(rig->num_cameras(), 5);
  for (int c = 0; c < 5; ++c) {
    const PinholeCamera cam = rig->CameraAt(c, 0.0);
    EXPECT_NEAR(cam.Centre().norm(), 0.7, 1e-9);
    const Eigen::Vector2d target = cam.Project(Eigen::Vector3d::Zero());
    EXPECT_NEAR(target.x(), cam.cx, 1e-6);
    EXPECT_NEAR(target.y(), cam.cy, 1e-6);
  }
  // The outer cameras sit at +-60 degrees of azimuth.
  EXPECT_NEAR(std::atan2(rig->CameraAt(4, 0).Centre().x(), rig->CameraAt(4, 0).Centre().z()) * 180 / M_PI, 60.0, 1e-6);
}

TEST(Scene, ErrorsNameTheKey) {
  Scene scene;
  Status s = ParseScene("effects = [\"sepia\"]\n", "a.toml", &scene);
  EXPECT_NE(s.message().find("unknown effect 'sepia'"), std::string::npos) << s.message();
  s = ParseScene("[head]\nyaw = { type = \"wobble\" }\n", "b.toml", &scene);
  EXPECT_NE(s.message().find("unknown curve type 'wobble'"), std::string::npos) << s.message();
  s = ParseScene("[camera.intrinsics]\nwidth = \"wide\"\n", "c.toml", &scene);
  EXPECT_NE(s.message().find("camera.intrinsics.width"), std::string::npos) << s.message();
  s = ParseScene("fps = [\n", "d.toml", &scene);
  EXPECT_NE(s.message().find("d.toml"), std::string::npos) << s.message();
  s = ParseScene("[camera.intrinsics]\nwidth = 0\n", "e.toml", &scene);
  EXPECT_EQ(s.code(), Status::Code::kInvalidArgument);
}

TEST(Curves, KeysBlinkAndTalkingStayInRange) {
  Curve keys;
  CurveTerm k;
  k.type = "keys";
  k.times = {0.0, 1.0};
  k.values = {0.0, 1.0};
  keys.terms = {k};
  EXPECT_DOUBLE_EQ(keys.Evaluate(-1.0), 0.0);
  EXPECT_DOUBLE_EQ(keys.Evaluate(0.5), 0.5);
  EXPECT_DOUBLE_EQ(keys.Evaluate(2.0), 1.0);
  Curve blink, talk;
  CurveTerm b;
  b.type = "blink";
  b.period = 2.0;
  b.duration = 0.2;
  blink.terms = {b};
  CurveTerm t;
  t.type = "talking";
  t.amplitude = 0.7;
  talk.terms = {t};
  double blink_max = 0, talk_max = 0, closed = 0;
  for (double time = 0; time < 10; time += 0.01) {
    const double v = blink.Evaluate(time), w = talk.Evaluate(time);
    EXPECT_GE(v, 0.0);
    EXPECT_LE(v, 1.0);
    EXPECT_GE(w, 0.0);
    EXPECT_LE(w, 0.7 + 1e-9);
    blink_max = std::max(blink_max, v);
    talk_max = std::max(talk_max, w);
    closed += v > 0.5;
  }
  EXPECT_GT(blink_max, 0.95);
  EXPECT_GT(talk_max, 0.4);
  EXPECT_LT(closed, 100);  // eyes closed a small part of the time
}

}  // namespace
}  // namespace headforge
