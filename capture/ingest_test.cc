// The ingest stage on real GRID clips, and every bad input failing cleanly.
#include "capture/ingest.h"

#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "capture/capture_io.h"
#include "capture/test_util.h"
#include "core/json_io.h"
#include "core/paths.h"

namespace headforge {
namespace {

using headforge::testing::GridClip;
using headforge::testing::GridFrames;
using headforge::testing::ScratchDir;

IngestOptions Defaults(std::vector<std::string> inputs) {
  IngestOptions options;
  options.inputs = std::move(inputs);
  options.resolution = 192;  // small: the tests check logic, not pixels
  ResolveIngestDefaults(DefaultDataDir(), &options);
  return options;
}

Status Ingest(const IngestOptions& options, const fs::path& out, IngestSummary* summary = nullptr) {
  NullProgress progress;
  IngestSummary local;
  return RunIngest(options, out, 2, &progress, summary ? summary : &local);
}

// Writes frames as an image folder.
fs::path WriteFolder(const fs::path& dir, const std::vector<cv::Mat>& frames) {
  fs::create_directories(dir);
  for (size_t i = 0; i < frames.size(); ++i) {
    char name[32];
    std::snprintf(name, sizeof(name), "f%04zu.png", i);
    cv::imwrite((dir / name).string(), frames[i]);
  }
  return dir;
}

void ExpectFailure(const Status& status, Status::Code code, const std::vector<std::string>& words) {
  ASSERT_FALSE(status.ok());
  EXPECT_EQ(status.code(), code) << status.message();
  for (const auto& w : words) EXPECT_NE(status.message().find(w), std::string::npos) << status.message();
}

// capture.json and landmarks.json read into their record and written again
// give the same bytes: the reader keeps everything ingest wrote.
void ExpectRewritesIdentically(const fs::path& out) {
  IngestedCapture capture;
  const Status read = ReadIngestedCapture(out, &capture);
  ASSERT_TRUE(read.ok()) << read.message();
  const fs::path again = out.parent_path() / (out.filename().string() + "_rewritten");
  fs::create_directories(again);
  ASSERT_TRUE(WriteIngestedCapture(capture, again).ok());
  for (const char* name : {"capture.json", "landmarks.json"}) {
    std::string first, second;
    ASSERT_TRUE(ReadFileToString(out / name, &first).ok());
    ASSERT_TRUE(ReadFileToString(again / name, &second).ok());
    EXPECT_EQ(first, second) << name;
  }
}

TEST(Ingest, GridClipSampledAndCropped) {
  const fs::path out = ScratchDir();
  IngestOptions options = Defaults({GridClip("bbaf2n").string()});
  options.fps = 12.5;  // every second frame
  IngestSummary summary;
  ASSERT_TRUE(Ingest(options, out, &summary).ok());
  EXPECT_EQ(summary.sampled, 38);
  EXPECT_EQ(summary.kept + summary.dropped_blur, 38);
  EXPECT_GE(summary.with_landmarks, 0.95 * summary.kept);
  nlohmann::json capture, landmarks;
  ASSERT_TRUE(ReadJson(out / "capture.json", &capture).ok());
  ASSERT_TRUE(ReadJson(out / "landmarks.json", &landmarks).ok());
  // One video: the default (auto) crop is one square around the head.
  EXPECT_EQ(summary.crop, "sequence");
  EXPECT_EQ(capture["crop_mode"], "sequence");
  EXPECT_LT(capture["cameras"][0]["crop"]["width"].get<double>(), 288.0);
  const auto& frames = capture["cameras"][0]["frames"];
  ASSERT_EQ(frames.size(), static_cast<size_t>(summary.kept));
  EXPECT_EQ(frames[1]["source_frame"].get<int>() - frames[0]["source_frame"].get<int>(), 2);
  const cv::Mat first = cv::imread((out / "frames" / "cam0" / "000000.png").string());
  EXPECT_EQ(first.size(), cv::Size(192, 192));
  const cv::Mat mask = cv::imread((out / "masks" / "cam0" / "000000.png").string(), cv::IMREAD_GRAYSCALE);
  EXPECT_EQ(mask.size(), cv::Size(192, 192));
  // Landmarks are in output pixels: inside the frame and inside the mask.
  for (const auto& p : landmarks["cameras"]["cam0"][0]["points"]) {
    const cv::Point2f q(p[0].get<float>(), p[1].get<float>());
    EXPECT_TRUE(cv::Rect2f(0, 0, 192, 192).contains(q));
  }
}

// The face mesh beside the 68 points, read back from landmarks.json: on a
// real face, where both name the same place (eye corners, nose tip, mouth
// corners, chin), the two agree to a few per cent of the eyes' distance
// apart (measured: median 2.2 %, the definitions differ a little); the
// selfie network's matte covers the points.
TEST(Ingest, TheFaceMeshLiesWhereThe68PointsAre) {
  const fs::path out = ScratchDir();
  IngestOptions options = Defaults({GridClip("bbaf2n").string()});
  options.max_frames = 12;
  options.matte = "selfie";
  IngestSummary summary;
  ASSERT_TRUE(Ingest(options, out, &summary).ok());
  EXPECT_EQ(summary.masks, "selfie");
  EXPECT_EQ(summary.with_mesh, summary.with_landmarks);
  IngestedCapture capture;
  ASSERT_TRUE(ReadIngestedCapture(out, &capture).ok());
  // (mesh index, iBUG index): eye outer corners, nose tip, mouth corners, chin.
  const std::pair<int, int> same[] = {{33, 36}, {263, 45}, {1, 30}, {61, 48}, {291, 54}, {152, 8}};
  std::vector<double> errors;
  for (const IngestedFrame& f : capture.cameras[0].frames) {
    ASSERT_TRUE(f.landmarks.has_value());
    ASSERT_EQ(f.mesh.size(), 468u);
    EXPECT_GT(f.mesh_score, 0.9f);
    const Landmarks68& lm = *f.landmarks;
    const double eyes = cv::norm(lm[ibug::kRightEyeOuter] - lm[ibug::kLeftEyeOuter]);
    for (const auto& [m, i] : same)
      errors.push_back(cv::norm(cv::Point2f(f.mesh[m].x, f.mesh[m].y) - lm[i]) / eyes);
    const cv::Mat mask = cv::imread(capture.MaskPath("cam0", f.index).string(), cv::IMREAD_GRAYSCALE);
    int inside = 0;
    for (const cv::Point3f& p : f.mesh)
      inside += mask.at<uchar>(std::clamp(int(p.y), 0, mask.rows - 1), std::clamp(int(p.x), 0, mask.cols - 1)) > 0;
    EXPECT_GT(inside, 460) << "frame " << f.index;
  }
  std::nth_element(errors.begin(), errors.begin() + errors.size() / 2, errors.end());
  std::printf("face mesh against the 68 points: median %.3f of the eyes' distance\n", errors[errors.size() / 2]);
  EXPECT_LT(errors[errors.size() / 2], 0.06);
  // Without the mesh (--face-mesh off) the frames hold none.
  options.face_mesh = "off";
  const fs::path plain = out / "plain";
  ASSERT_TRUE(Ingest(options, plain, &summary).ok());
  EXPECT_EQ(summary.with_mesh, 0);
  ASSERT_TRUE(ReadIngestedCapture(plain, &capture).ok());
  EXPECT_TRUE(capture.cameras[0].frames[0].mesh.empty());
}

TEST(Ingest, DropsTheFrameBlurredOnPurposeAndSaysWhy) {
  const fs::path dir = ScratchDir();
  auto frames = GridFrames("brbk7n", 20);
  cv::GaussianBlur(frames[7], frames[7], cv::Size(0, 0), 2.5);
  const fs::path folder = WriteFolder(dir / "in", frames);
  IngestSummary summary;
  ASSERT_TRUE(Ingest(Defaults({folder.string()}), dir / "out", &summary).ok());
  EXPECT_EQ(summary.sampled, 20);
  EXPECT_EQ(summary.kept, 19);
  EXPECT_EQ(summary.dropped_blur, 1);
  nlohmann::json capture;
  ASSERT_TRUE(ReadJson(dir / "out" / "capture.json", &capture).ok());
  ASSERT_EQ(capture["dropped"].size(), 1u);
  EXPECT_EQ(capture["dropped"][0]["reason"], "blur");
  EXPECT_EQ(capture["dropped"][0]["source_frames"]["cam0"], 7);
  EXPECT_NE(capture["dropped"][0]["detail"].get<std::string>().find("median"), std::string::npos);
  // Frame 8 of the source became output frame 7.
  EXPECT_EQ(capture["cameras"][0]["frames"][7]["source_frame"], 8);
  ExpectRewritesIdentically(dir / "out");
}

TEST(Ingest, FramesWithoutAFaceAreKeptMarkedAndCounted) {
  const fs::path dir = ScratchDir();
  auto frames = GridFrames("lrwp9a", 12);
  cv::theRNG().state = 3;
  for (int i : {4, 5, 9}) cv::randu(frames[i], cv::Scalar::all(0), cv::Scalar::all(255));  // sharp, faceless
  const fs::path folder = WriteFolder(dir / "in", frames);
  IngestOptions options = Defaults({folder.string()});
  options.blur_ratio = 0.0;
  IngestSummary summary;
  ASSERT_TRUE(Ingest(options, dir / "out", &summary).ok());
  EXPECT_EQ(summary.kept, 12);
  EXPECT_EQ(summary.face_lost, 3);
  EXPECT_EQ(summary.with_landmarks, 9);
  nlohmann::json landmarks, capture;
  ASSERT_TRUE(ReadJson(dir / "out" / "landmarks.json", &landmarks).ok());
  ASSERT_TRUE(ReadJson(dir / "out" / "capture.json", &capture).ok());
  for (int i = 0; i < 12; ++i) {
    const bool lost = i == 4 || i == 5 || i == 9;
    EXPECT_EQ(landmarks["cameras"]["cam0"][i]["found"].get<bool>(), !lost) << i;
    EXPECT_EQ(capture["cameras"][0]["frames"][i]["face"], lost ? "lost" : "found") << i;
  }
  EXPECT_EQ(capture["report"]["face_lost"], 3);
  EXPECT_TRUE(fs::exists(dir / "out" / "masks" / "cam0" / "000004.png"));
  ExpectRewritesIdentically(dir / "out");
}

TEST(Ingest, FollowingCropsAreRecordedPerFrame) {
  const fs::path dir = ScratchDir();
  IngestOptions options = Defaults({WriteFolder(dir / "in", GridFrames("bbaf2n", 6)).string()});
  options.crop = "frame";
  options.resolution = 96;
  ASSERT_TRUE(Ingest(options, dir / "out").ok());
  IngestedCapture capture;
  ASSERT_TRUE(ReadIngestedCapture(dir / "out", &capture).ok());
  ASSERT_EQ(capture.num_frames(), 6);
  EXPECT_FALSE(capture.cameras[0].fixed_crop);
  for (const IngestedFrame& f : capture.cameras[0].frames) {
    ASSERT_TRUE(f.crop.has_value());
    EXPECT_EQ(f.crop->output, cv::Size(96, 96));
    EXPECT_FALSE(f.source_file.empty());
  }
  ExpectRewritesIdentically(dir / "out");
  // A capture.json of another version is refused, naming the stage to rerun.
  nlohmann::json json;
  ASSERT_TRUE(ReadJson(dir / "out" / "capture.json", &json).ok());
  json["version"] = 1;
  ASSERT_TRUE(WriteJsonAtomic(dir / "out" / "capture.json", json).ok());
  ExpectFailure(ReadIngestedCapture(dir / "out", &capture), Status::Code::kDataError,
                {"capture.json", "version 1", "run headforge ingest again"});
}

TEST(Ingest, SynchronisesCamerasByOffsets) {
  const fs::path dir = ScratchDir();
  const auto frames = GridFrames("sbwe5n", 16);
  const std::vector<cv::Mat> a(frames.begin(), frames.begin() + 12);
  const std::vector<cv::Mat> b(frames.begin() + 3, frames.end());  // b[j] = a[j + 3]
  IngestOptions options = Defaults({WriteFolder(dir / "a", a).string(), WriteFolder(dir / "b", b).string()});
  options.offsets = {3, 0};  // cam0's frame j+3 pairs with cam1's frame j
  options.blur_ratio = 0.0;
  IngestSummary summary;
  ASSERT_TRUE(Ingest(options, dir / "out", &summary).ok());
  EXPECT_EQ(summary.cameras, 2);
  // Several videos: the default (auto) crop keeps each whole frame (360x288 to 192x154).
  EXPECT_EQ(summary.crop, "none");
  EXPECT_EQ(cv::imread((dir / "out" / "frames" / "cam1" / "000000.png").string()).size(), cv::Size(192, 154));
  // Samples 0..2 have no cam0 frame (offset 3 reaches past cam0's 12 frames only at the end):
  // cam0 frames 3..11 pair with cam1 frames 0..8 -> 9 synchronised frames.
  EXPECT_EQ(summary.kept, 9);
  EXPECT_EQ(summary.dropped_missing, summary.sampled - 9);
  for (int i = 0; i < summary.kept; ++i) {
    char name[32];
    std::snprintf(name, sizeof(name), "%06d.png", i);
    const cv::Mat f0 = cv::imread((dir / "out" / "frames" / "cam0" / name).string());
    const cv::Mat f1 = cv::imread((dir / "out" / "frames" / "cam1" / name).string());
    ASSERT_FALSE(f0.empty());
    EXPECT_EQ(cv::norm(f0, f1, cv::NORM_INF), 0.0) << "frame " << i;
  }
  ExpectRewritesIdentically(dir / "out");
}

TEST(Ingest, UsesTheUsersMasks) {
  const fs::path dir = ScratchDir();
  const auto frames = GridFrames("swiz3n", 6);
  std::vector<cv::Mat> masks;
  for (const auto& f : frames) {
    cv::Mat m(f.size(), CV_8U, cv::Scalar(0));
    m(cv::Rect(0, 0, f.cols / 2, f.rows)).setTo(255);  // left half
    masks.push_back(m);
  }
  IngestOptions options = Defaults({WriteFolder(dir / "in", frames).string()});
  options.masks = WriteFolder(dir / "masks", masks).string();
  options.crop = "none";
  ASSERT_TRUE(Ingest(options, dir / "out").ok());
  const cv::Mat mask = cv::imread((dir / "out" / "masks" / "cam0" / "000002.png").string(), cv::IMREAD_GRAYSCALE);
  ASSERT_FALSE(mask.empty());
  EXPECT_EQ(mask.at<uchar>(mask.rows / 2, 5), 255);
  EXPECT_EQ(mask.at<uchar>(mask.rows / 2, mask.cols - 5), 0);
  nlohmann::json capture;
  ASSERT_TRUE(ReadJson(dir / "out" / "capture.json", &capture).ok());
  EXPECT_EQ(capture["cameras"][0]["masks"], "user");
}

// A camera of several that never sees the face (one behind the head in a
// dome) is kept whole, without landmarks, when masks are given; without
// them the error says so.
TEST(Ingest, ACameraThatNeverSeesTheFaceIsKeptWithTheUsersMasks) {
  const fs::path dir = ScratchDir();
  const auto frames = GridFrames("swiz3n", 6);
  std::vector<cv::Mat> back, masks;
  for (const auto& f : frames) {
    back.emplace_back(f.size(), CV_8UC3, cv::Scalar(60, 50, 40));  // the back of a head: no face
    cv::Mat m(f.size(), CV_8U, cv::Scalar(0));
    m(cv::Rect(f.cols / 4, f.rows / 4, f.cols / 2, f.rows / 2)).setTo(255);
    masks.push_back(m);
  }
  IngestOptions options = Defaults({WriteFolder(dir / "front", frames).string(), WriteFolder(dir / "back", back).string()});
  options.blur_ratio = 0.0;
  ExpectFailure(Ingest(options, dir / "refused"), Status::Code::kDataError, {"no face found", "--mask-folder"});
  WriteFolder(dir / "masks" / "cam0", masks);
  WriteFolder(dir / "masks" / "cam1", masks);
  options.masks = (dir / "masks").string();
  IngestSummary summary;
  ASSERT_TRUE(Ingest(options, dir / "out", &summary).ok());
  EXPECT_EQ(summary.cameras, 2);
  EXPECT_EQ(summary.crop, "none");
  EXPECT_EQ(summary.face_lost, 6);  // every frame of the back camera
  IngestedCapture capture;
  ASSERT_TRUE(ReadIngestedCapture(dir / "out", &capture).ok());
  ASSERT_EQ(capture.cameras.size(), 2u);
  for (const auto& frame : capture.cameras[1].frames) EXPECT_FALSE(frame.landmarks.has_value()) << frame.index;
  int with_landmarks = 0;
  for (const auto& frame : capture.cameras[0].frames) with_landmarks += frame.landmarks.has_value();
  EXPECT_EQ(with_landmarks, 6);
  const cv::Mat mask = cv::imread(capture.MaskPath("cam1", capture.cameras[1].frames[2].index).string(),
                                  cv::IMREAD_GRAYSCALE);
  ASSERT_FALSE(mask.empty());
  EXPECT_EQ(mask.at<uchar>(mask.rows / 2, mask.cols / 2), 255);
  EXPECT_EQ(mask.at<uchar>(2, 2), 0);
}

// A long recording in which one pose is held for a long time: 60 copies of
// a GRID clip's first frame, then the clip's 75 frames (the man talking).
// Kept to 24 frames for coverage, at most two come from the held pose
// (sampling in time would take 11 of them), the rest from the talking, in
// time order; the others are recorded as unselected.
TEST(Ingest, ALongRecordingKeepsFramesForWhatTheyShowNotForHowLongTheyLast) {
  std::vector<cv::Mat> frames = GridFrames("bbaf2n", 75);
  ASSERT_EQ(frames.size(), 75u);
  frames.insert(frames.begin(), 60, frames[0].clone());
  const fs::path out = ScratchDir();
  IngestOptions options = Defaults({WriteFolder(out / "input", frames).string()});
  options.select = 24;
  IngestSummary summary;
  ASSERT_TRUE(Ingest(options, out / "ws", &summary).ok());
  IngestedCapture capture;
  ASSERT_TRUE(ReadIngestedCapture(out / "ws", &capture).ok());
  ASSERT_EQ(capture.samples.size(), 24u);
  EXPECT_EQ(summary.kept, 24);
  EXPECT_EQ(summary.dropped_unselected + summary.dropped_blur + 24, 135);
  int held = 0;
  for (size_t i = 0; i < capture.samples.size(); ++i) {
    held += capture.samples[i] < 60 ? 1 : 0;
    if (i > 0) {
      EXPECT_LT(capture.samples[i - 1], capture.samples[i]);
    }
  }
  EXPECT_LE(held, 2);
  int unselected = 0;
  for (const DroppedSample& d : capture.dropped) unselected += d.reason == "unselected" ? 1 : 0;
  EXPECT_EQ(unselected, summary.dropped_unselected);
}

// A recording in which the face is missing from half of the frames (a
// camera going round the head, here black frames between the clip's): kept
// to 20, the frames are chosen evenly in time, which COLMAP's matching of
// neighbours needs, not by the face.
TEST(Ingest, ARecordingHalfWithoutTheFaceIsSelectedEvenlyInTime) {
  std::vector<cv::Mat> clip = GridFrames("bbaf2n", 40), frames;
  ASSERT_EQ(clip.size(), 40u);
  for (const cv::Mat& f : clip) {
    frames.push_back(f);
    frames.push_back(cv::Mat::zeros(f.size(), f.type()));
  }
  const fs::path out = ScratchDir();
  IngestOptions options = Defaults({WriteFolder(out / "input", frames).string()});
  options.select = 20;
  options.blur_ratio = 0;  // the black frames have no sharpness
  ASSERT_TRUE(Ingest(options, out / "ws").ok());
  IngestedCapture capture;
  ASSERT_TRUE(ReadIngestedCapture(out / "ws", &capture).ok());
  ASSERT_EQ(capture.samples.size(), 20u);
  for (size_t i = 0; i < capture.samples.size(); ++i) EXPECT_EQ(capture.samples[i], int(4 * i)) << i;
}

TEST(IngestBadInput, MissingFile) {
  ExpectFailure(Ingest(Defaults({"/no/such/video.mp4"}), ScratchDir()), Status::Code::kNotFound,
                {"/no/such/video.mp4"});
}

TEST(IngestBadInput, CorruptFile) {
  const fs::path dir = ScratchDir();
  std::string noise(20000, '\0');
  for (size_t i = 0; i < noise.size(); ++i) noise[i] = static_cast<char>((i * 7919u) >> 3);
  ASSERT_TRUE(WriteFileAtomic(dir / "corrupt.mp4", noise).ok());
  ExpectFailure(Ingest(Defaults({(dir / "corrupt.mp4").string()}), dir / "out"), Status::Code::kDataError,
                {"corrupt.mp4"});
}

TEST(IngestBadInput, TruncatedVideoWithoutDecodableFrame) {
  const fs::path dir = ScratchDir();
  std::string bytes;
  ASSERT_TRUE(ReadFileToString(GridClip("bbaf2n"), &bytes).ok());
  ASSERT_TRUE(WriteFileAtomic(dir / "cut.mpg", bytes.substr(0, 2048)).ok());
  ExpectFailure(Ingest(Defaults({(dir / "cut.mpg").string()}), dir / "out"), Status::Code::kDataError,
                {"cut.mpg"});
}

TEST(IngestBadInput, EmptyFileAndEmptyFolder) {
  const fs::path dir = ScratchDir();
  ASSERT_TRUE(WriteFileAtomic(dir / "empty.mp4", "").ok());
  ExpectFailure(Ingest(Defaults({(dir / "empty.mp4").string()}), dir / "out"), Status::Code::kDataError,
                {"empty"});
  fs::create_directories(dir / "nothing");
  ExpectFailure(Ingest(Defaults({(dir / "nothing").string()}), dir / "out"), Status::Code::kDataError,
                {"no images"});
}

TEST(IngestBadInput, UnreadableFile) {
  const fs::path dir = ScratchDir();
  fs::copy_file(GridClip("bbaf2n"), dir / "locked.mpg");
  fs::permissions(dir / "locked.mpg", fs::perms::none);
  fs::permissions(dir, fs::perms::all);
  // root reads anything: check as an unprivileged user in a child process.
  const pid_t child = fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    if (::geteuid() == 0 && (::setgid(65534) != 0 || ::setuid(65534) != 0)) _exit(3);
    const Status status = Ingest(Defaults({(dir / "locked.mpg").string()}), "/tmp/hf_never_written");
    const bool clear = status.code() == Status::Code::kIoError &&
                       status.message().find("locked.mpg") != std::string::npos &&
                       status.message().find("permission denied") != std::string::npos;
    _exit(clear ? 0 : 1);
  }
  int wstatus = 0;
  waitpid(child, &wstatus, 0);
  ASSERT_TRUE(WIFEXITED(wstatus));
  EXPECT_EQ(WEXITSTATUS(wstatus), 0);
}

TEST(IngestBadInput, VideoWithoutAFace) {
  const fs::path dir = ScratchDir();
  const fs::path video = dir / "no_face.avi";
  {
    cv::VideoWriter writer(video.string(), cv::CAP_FFMPEG, cv::VideoWriter::fourcc('M', 'J', 'P', 'G'),
                           25.0, cv::Size(320, 240));
    ASSERT_TRUE(writer.isOpened());
    cv::theRNG().state = 11;
    for (int i = 0; i < 10; ++i) {
      cv::Mat frame(240, 320, CV_8UC3);
      cv::randu(frame, cv::Scalar::all(0), cv::Scalar::all(255));
      writer.write(frame);
    }
  }
  ExpectFailure(Ingest(Defaults({video.string()}), dir / "out"), Status::Code::kDataError,
                {"no face found", "no_face.avi", "Try"});
}

TEST(IngestBadInput, EmptyTimeRange) {
  IngestOptions options = Defaults({GridClip("bbaf2n").string()});
  options.start = 10.0;  // the clip lasts 3 s
  ExpectFailure(Ingest(options, ScratchDir()), Status::Code::kDataError, {"time range", "bbaf2n.mpg"});
  options.start = 2.0;
  options.end = 1.0;
  ExpectFailure(options.Check(), Status::Code::kInvalidArgument, {"empty time range"});
}

TEST(IngestBadInput, NonPositiveResolutionAndOtherBadOptions) {
  IngestOptions options = Defaults({GridClip("bbaf2n").string()});
  options.resolution = 0;
  ExpectFailure(Ingest(options, ScratchDir()), Status::Code::kInvalidArgument, {"--frame-size"});
  options.resolution = -5;
  ExpectFailure(options.Check(), Status::Code::kInvalidArgument, {"--frame-size"});
  options = Defaults({});
  ExpectFailure(options.Check(), Status::Code::kInvalidArgument, {"--video"});
  options = Defaults({"a", "b"});
  options.offsets = {1};
  ExpectFailure(options.Check(), Status::Code::kInvalidArgument, {"--offsets"});
}

TEST(IngestInputs, FingerprintChangesWithOptionsAndInputsOnly) {
  const fs::path dir = ScratchDir();
  fs::copy_file(GridClip("bbaf2n"), dir / "clip.mpg");
  IngestOptions options = Defaults({(dir / "clip.mpg").string()});
  auto fingerprint = [&](const IngestOptions& o) {
    OptionSet set;
    IngestOptions bound = o;
    AddIngestOptions(&set, &bound);
    Hasher h;
    h.Add(set.ToIni("ingest", true));
    EXPECT_TRUE(AddIngestInputs(bound, &h).ok());
    return h.Hex();
  };
  const std::string base = fingerprint(options);
  EXPECT_EQ(fingerprint(options), base);
  IngestOptions changed = options;
  changed.fps = 5.0;
  EXPECT_NE(fingerprint(changed), base);
  changed = options;
  changed.resolution = 256;
  EXPECT_NE(fingerprint(changed), base);
  changed = options;
  changed.landmark_model = options.landmark_model;  // runtime path, same file
  EXPECT_EQ(fingerprint(changed), base);
  // A different video under the same name changes it.
  fs::copy_file(GridClip("lbax4n"), dir / "clip.mpg", fs::copy_options::overwrite_existing);
  EXPECT_NE(fingerprint(options), base);
}

}  // namespace
}  // namespace headforge
