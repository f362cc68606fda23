// The face metrics: face-api's recognition network in LibTorch against face-api's own
// JavaScript on the same crops (node); identity on real faces, GRID's
// speakers, whose identities are known (ten speakers; id2_vcd_swwp2s and
// pwij3p are the same man); both metrics on held-out strips as training
// writes them.
#include <gtest/gtest.h>
#include <torch/torch.h>

#include <cmath>
#include <cstdlib>

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>

#include "avatar/face_metrics.h"
#include "avatar/metrics/face_recognition.h"
#include "core/json_io.h"
#include "core/paths.h"

namespace headforge {
namespace {

fs::path Scratch() {
  const fs::path dir = fs::temp_directory_path() / "hf_face_metrics_test";
  fs::create_directories(dir);
  return dir;
}

#ifdef HEADFORGE_FACE_API
// Frame `index` of a GRID clip.
cv::Mat GridFrame(const std::string& clip, int index) {
  cv::VideoCapture video(DefaultDataDir() + "/video/grid/" + clip + ".mpg");
  cv::Mat frame;
  for (int i = 0; i <= index; ++i) video.read(frame);
  return frame;
}

std::unique_ptr<FaceMetrics> LoadMetrics() {
  FaceMetricsOptions options;
  options.face_api_models = fs::path(HEADFORGE_FACE_API) / "model";
  options.landmark_model = DefaultLandmarkModel();
  options.ultraface_dir = DefaultDataDir() + "/models/ultraface";
  std::unique_ptr<FaceMetrics> metrics;
  const Status s = FaceMetrics::Load(options, &metrics);
  EXPECT_TRUE(s.ok()) << s.message();
  return metrics;
}

// The crop of the face in a GRID frame.
cv::Mat GridCrop(FaceMetrics& metrics, const std::string& clip, int index) {
  const cv::Mat frame = GridFrame(clip, index);
  FaceMetrics::Face face;
  EXPECT_TRUE(metrics.FindFace(frame, &face)) << clip;
  return FaceMetrics::Crop(frame, face.square);
}

#ifdef HEADFORGE_NODE
TEST(FaceRecognition, MatchesFaceApiOwnJavaScriptOnTheSameCrops) {
  std::unique_ptr<FaceMetrics> metrics = LoadMetrics();
  ASSERT_TRUE(metrics);
  const std::vector<cv::Mat> crops = {GridCrop(*metrics, "bbaf2n", 10), GridCrop(*metrics, "lbax4n", 40),
                                      GridCrop(*metrics, "sbwe5n", 20)};
  std::string command = std::string("'") + HEADFORGE_NODE + "' '" + HEADFORGE_FACE_DESCRIPTORS_SCRIPT + "' '" +
                        (Scratch() / "js.json").string() + "'";
  for (size_t i = 0; i < crops.size(); ++i) {
    const fs::path ppm = Scratch() / ("crop" + std::to_string(i) + ".ppm");
    ASSERT_TRUE(cv::imwrite(ppm.string(), crops[i]));
    command += " '" + ppm.string() + "'";
  }
  command += std::string(" --modules '") + HEADFORGE_NODE_MODULES + "'";
  ASSERT_EQ(std::system(command.c_str()), 0) << command;
  nlohmann::json js;
  ASSERT_TRUE(ReadJson(Scratch() / "js.json", &js).ok());
  const std::vector<std::vector<float>> ours = metrics->Describe(crops);
  ASSERT_EQ(js["descriptors"].size(), crops.size());
  for (size_t i = 0; i < crops.size(); ++i) {
    const std::vector<float> theirs = js["descriptors"][i].get<std::vector<float>>();
    ASSERT_EQ(theirs.size(), 128u);
    double worst = 0, size = 0;
    for (size_t k = 0; k < 128; ++k) {
      worst = std::max(worst, double(std::abs(ours[i][k] - theirs[k])));
      size = std::max(size, double(std::abs(theirs[k])));
    }
    // Float32 in both, summed in different orders: entries of about 0.1 agree
    // to 1e-4 (measured: a few 1e-6).
    EXPECT_LT(worst, 1e-4) << "crop " << i << " (largest entry " << size << ")";
    EXPECT_GT(DescriptorCosine(ours[i], theirs), 0.99999) << i;
  }
}
#endif

TEST(FaceRecognition, TellsOnePersonFromAnother) {
  std::unique_ptr<FaceMetrics> metrics = LoadMetrics();
  ASSERT_TRUE(metrics);
  const std::vector<std::vector<float>> d = metrics->Describe(
      {GridCrop(*metrics, "bbaf2n", 10), GridCrop(*metrics, "bbaf2n", 60), GridCrop(*metrics, "id2_vcd_swwp2s", 10),
       GridCrop(*metrics, "pwij3p", 10), GridCrop(*metrics, "lbax4n", 10), GridCrop(*metrics, "swiz3n", 10)});
  // One speaker in two frames, one man in two clips: near 1 (measured 0.995,
  // 0.981); two people: lower (measured 0.80-0.92), every pair of two
  // people below both pairs of one.
  const double same1 = DescriptorCosine(d[0], d[1]), same2 = DescriptorCosine(d[2], d[3]);
  EXPECT_GT(same1, 0.97);
  EXPECT_GT(same2, 0.97);
  for (size_t i = 0; i < d.size(); ++i)
    for (size_t j = i + 1; j < d.size(); ++j) {
      if ((i == 0 && j == 1) || (i == 2 && j == 3)) continue;
      EXPECT_LT(DescriptorCosine(d[i], d[j]), 0.95) << i << " " << j;
      EXPECT_LT(DescriptorCosine(d[i], d[j]), std::min(same1, same2) - 0.03) << i << " " << j;
    }
  EXPECT_NEAR(DescriptorCosine(d[0], d[0]), 1.0, 1e-12);
}

TEST(FaceRecognition, ScoresHeldOutStripsRenderAgainstFrame) {
  std::unique_ptr<FaceMetrics> metrics = LoadMetrics();
  ASSERT_TRUE(metrics);
  const fs::path held = Scratch() / "held_out";
  fs::remove_all(held);
  fs::create_directories(held);
  // render | frame | error, as training writes them: a render that is the
  // frame, one of another speaker, and a frame with no face.
  const cv::Mat frame = GridFrame("bbaf2n", 30)(cv::Rect(52, 0, 256, 256)).clone();
  const cv::Mat other = GridFrame("swiz3n", 30)(cv::Rect(52, 0, 256, 256)).clone();
  const cv::Mat grey(256, 256, CV_8UC3, cv::Scalar(128, 128, 128));
  auto strip = [&](const cv::Mat& render, const cv::Mat& truth, const std::string& name) {
    cv::Mat out;
    cv::hconcat(std::vector<cv::Mat>{render, truth, grey}, out);
    ASSERT_TRUE(cv::imwrite((held / name).string(), out));
  };
  // The frame moved 6 px to the right: the landmarks follow it.
  cv::Mat moved;
  const cv::Mat shift = (cv::Mat_<double>(2, 3) << 1, 0, 6, 0, 1, 0);
  cv::warpAffine(frame, moved, shift, frame.size(), cv::INTER_LINEAR, cv::BORDER_REPLICATE);
  strip(frame, frame, "cam0_000001.png");
  strip(other, frame, "cam0_000002.png");
  strip(frame, grey, "cam0_000003.png");
  strip(moved, frame, "cam0_000004.png");
  HeldOutFaceScores scores;
  ASSERT_TRUE(ScoreHeldOutFaces(*metrics, held, &scores).ok());
  EXPECT_EQ(scores.views, 4);
  EXPECT_EQ(scores.scored, 3);
  ASSERT_EQ(scores.per_view.size(), 4u);
  EXPECT_EQ(scores.per_view[0].view, "cam0_000001");
  EXPECT_EQ(scores.image_size, 256);
  // The render that is the frame: the same face, the same landmarks.
  EXPECT_NEAR(scores.per_view[0].cosine, 1.0, 1e-9);
  EXPECT_NEAR(scores.per_view[0].landmark_px, 0.0, 1e-9);
  // Another speaker: another face.
  EXPECT_LT(scores.per_view[1].cosine, 0.9);
  EXPECT_FALSE(scores.per_view[2].face);
  // Moved 6 px: F-LMD near 6 px, and the identity, cropped where the frame's
  // face is, a little lower than 1.
  EXPECT_NEAR(scores.per_view[3].landmark_px, 6.0, 1.5);
  EXPECT_LT(scores.per_view[3].cosine, 0.999);
  EXPECT_GT(scores.per_view[3].cosine, 0.9);
  const double n = 3;
  EXPECT_NEAR(scores.mean_cosine, (scores.per_view[0].cosine + scores.per_view[1].cosine + scores.per_view[3].cosine) / n,
              1e-12);
  EXPECT_NEAR(scores.mean_landmark_px,
              (scores.per_view[1].landmark_px + scores.per_view[3].landmark_px) / n, 1e-12);
  // Not a strip: said, not scored.
  ASSERT_TRUE(cv::imwrite((held / "cam0_000005.png").string(), cv::Mat(10, 10, CV_8UC3, cv::Scalar(0, 0, 0))));
  EXPECT_EQ(ScoreHeldOutFaces(*metrics, held, &scores).code(), Status::Code::kDataError);
}
#endif  // HEADFORGE_FACE_API

TEST(FaceRecognition, MissingWeightsSayHowToInstallThem) {
  FaceMetricsOptions options;
  options.face_api_models = Scratch() / "no_such_folder";
  std::unique_ptr<FaceMetrics> metrics;
  const Status s = FaceMetrics::Load(options, &metrics);
  EXPECT_EQ(s.code(), Status::Code::kNotFound);
  EXPECT_NE(s.message().find("install_deps"), std::string::npos) << s.message();
}

// The expression's landmark distance ignores where the face is, its size
// and its roll, and sees a mouth that opens.
TEST(FaceLandmarks, AlignedExpressionDistanceSeesTheExpressionAlone) {
  Landmarks68 face;
  for (int i = 0; i < 68; ++i)  // any layout; the rigid points must not be collinear
    face[size_t(i)] = cv::Point2f(100 + 40 * std::cos(0.37 * i) + i, 120 + 30 * std::sin(0.53 * i));
  Landmarks68 moved;
  const double c = std::cos(0.2), s = std::sin(0.2);
  for (size_t i = 0; i < 68; ++i)
    moved[i] = cv::Point2f(float(1.7 * (c * face[i].x - s * face[i].y) + 31),
                           float(1.7 * (s * face[i].x + c * face[i].y) - 12));
  EXPECT_NEAR(AlignedExpressionDistance(moved, face), 0.0, 1e-3);
  // The lower lip's 8 points down by a tenth of the eye-corner distance:
  // (8 * 10%) / 32 points = 2.5%.
  const double eyes = cv::norm(face[36] - face[45]);
  Landmarks68 open = face;
  for (int i : {55, 56, 57, 58, 59, 64, 65, 66}) open[size_t(i)].y += float(0.1 * eyes);
  EXPECT_NEAR(AlignedExpressionDistance(open, face), 2.5, 1e-3);
}

}  // namespace
}  // namespace headforge
