// The table of bad inputs (docs/tests.md#bad-inputs): each case runs the real
// program on something wrong and expects one clear line on stderr saying what
// happened and what to try, exit code 1 (the input) or 2 (the command line),
// and, where it runs on a tracked workspace, nothing already there lost. A
// second table holds inputs that are accepted with a warning.
#include <gtest/gtest.h>
#include <sys/file.h>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>

#include <cctype>
#include <cstdlib>
#include <functional>
#include <map>
#include <sstream>

#include "core/fs.h"
#include "tests/run_headforge.h"
#include "tests/shared_workspace.h"

namespace headforge {
namespace {

const fs::path kGrid = fs::path(HEADFORGE_TEST_SHARED_DATA) / "video" / "grid";

struct BadInput {
  std::string name;
  // Makes what the case needs in `dir` (a tracked workspace at dir/ws when
  // `on_workspace`) and gives the command line.
  std::function<std::vector<std::string>(const fs::path& dir)> make;
  int code;                  // the exit code expected
  std::vector<std::string> says;  // parts of the one line on stderr
  bool on_workspace = false;
};

void WriteText(const fs::path& path, const std::string& text) { ASSERT_TRUE(WriteFileAtomic(path, text).ok()); }

// `frames` frames of `size` from `paint` into an MJPEG .avi.
void WriteVideo(const fs::path& path, int frames, cv::Size size, const std::function<cv::Mat(int)>& paint) {
  cv::VideoWriter writer(path.string(), cv::CAP_FFMPEG, cv::VideoWriter::fourcc('M', 'J', 'P', 'G'), 25.0, size);
  ASSERT_TRUE(writer.isOpened()) << path;
  for (int i = 0; i < frames; ++i) writer.write(paint(i));
}

// The GRID clip's first `frames` frames, each scaled by `scale` onto a black
// canvas of the original size (a small face when scale is small).
void WriteGridFrames(const fs::path& path, int frames, double scale) {
  cv::VideoCapture in((kGrid / "bbaf2n.mpg").string(), cv::CAP_FFMPEG);
  ASSERT_TRUE(in.isOpened());
  cv::Mat first;
  ASSERT_TRUE(in.read(first));
  WriteVideo(path, frames, first.size(), [&](int i) {
    cv::Mat frame = first.clone();
    if (i > 0) in.read(frame);
    cv::Mat canvas = cv::Mat::zeros(frame.size(), frame.type()), small;
    cv::resize(frame, small, cv::Size(), scale, scale, cv::INTER_AREA);
    small.copyTo(canvas(cv::Rect((canvas.cols - small.cols) / 2, (canvas.rows - small.rows) / 2, small.cols,
                                 small.rows)));
    return canvas;
  });
}

void EditJson(const fs::path& path, const std::function<void(nlohmann::json*)>& edit) {
  nlohmann::json j;
  ASSERT_TRUE(ReadJson(path, &j).ok()) << path;
  edit(&j);
  WriteText(path, j.dump());
}

// An ingest command line into dir/w with `extra`.
std::vector<std::string> IngestArgs(const fs::path& dir, const std::vector<std::string>& extra) {
  std::vector<std::string> args = {"ingest", "--workspace", (dir / "w").string()};
  args.insert(args.end(), extra.begin(), extra.end());
  return args;
}

// The command line (exit 2).
std::vector<BadInput> CommandLineCases() {
  const auto video = IngestArgs;
  const std::string grid = (kGrid / "bbaf2n.mpg").string();
  return {
      {"an unknown command", [](const fs::path&) { return std::vector<std::string>{"frobnicate"}; }, 2,
       {"unknown command 'frobnicate'", "--help"}},
      {"an unknown option", [=](const fs::path& d) { return video(d, {"--video", grid, "--frobnicate", "1"}); }, 2,
       {"unrecognised option '--frobnicate'"}},
      {"ingest without a video", [=](const fs::path& d) { return video(d, {}); }, 2, {"--video"}},
      {"a negative frame rate", [=](const fs::path& d) { return video(d, {"--video", grid, "--fps", "-1"}); }, 2,
       {"--fps"}},
      {"a resolution of 0", [=](const fs::path& d) { return video(d, {"--video", grid, "--frame-size", "0"}); }, 2,
       {"--frame-size"}},
      {"an empty time range",
       [=](const fs::path& d) { return video(d, {"--video", grid, "--start", "2", "--end", "1"}); }, 2,
       {"empty time range"}},
      {"an unknown preset",
       [](const fs::path& d) {
         return std::vector<std::string>{"train", "--workspace", (d / "ws").string(), "--preset", "fast"};
       },
       2, {"--preset must be draft, standard or high"}, true},
      {"a hold-out of 2",
       [](const fs::path& d) {
         return std::vector<std::string>{"train", "--workspace", (d / "ws").string(), "--holdout", "2"};
       },
       2, {"--holdout must be in (0, 0.9)"}, true},
      {"a folder of masks given to train's --mask",
       [](const fs::path& d) {
         return std::vector<std::string>{"train", "--workspace", (d / "ws").string(), "--mask", (d / "my_masks").string()};
       },
       2, {"--mask must be auto, ingest, mesh or hull", "ingest's --mask-folder"}, true},
      {"an unknown camera among the held-out ones (comma-separated)",
       [](const fs::path& d) {
         return std::vector<std::string>{"train", "--workspace", (d / "ws").string(), "--holdout-cameras",
                                         "cam0,cam7", "--max-minutes", "0"};
       },
       2, {"no camera cam7 to hold out"}, true},
      {"an unknown model",
       [](const fs::path& d) {
         return std::vector<std::string>{"train", "--workspace", (d / "ws").string(), "--model", "nerf"};
       },
       2, {"--model must be gaussian-style or gan-avatar"}, true},
      {"an unknown device",
       [](const fs::path& d) {
         return std::vector<std::string>{"train", "--workspace", (d / "ws").string(), "--device", "tpu"};
       },
       2, {"'tpu' is not a device"}, true},
      {"train before align",
       [](const fs::path& d) {
         fs::create_directories(d / "fresh");
         WriteText(d / "fresh" / "workspace.json", R"({"version": 1, "stages": []})");
         return std::vector<std::string>{"train", "--workspace", (d / "fresh").string()};
       },
       2, {"needs the ingest stage first", "headforge run"}},
      {"a stage given a folder that holds no workspace",
       [](const fs::path& d) {
         return std::vector<std::string>{"track", "--workspace", (d / "mistyped").string()};
       },
       1, {"no workspace at", "mistyped (no workspace.json); headforge run --video FILE --workspace"}},
      {"a config file with a value of the wrong kind",
       [=](const fs::path& d) {
         WriteText(d / "bad.ini", "[ingest]\nfps = fast\n");
         return video(d, {"--video", grid, "--config", (d / "bad.ini").string()});
       },
       2, {"bad.ini", "fps"}},
      {"a config file that is not there",
       [=](const fs::path& d) { return video(d, {"--video", grid, "--config", (d / "none.ini").string()}); }, 2,
       {"none.ini"}},
      {"a workspace that is a file",
       [=](const fs::path& d) {
         WriteText(d / "file", "x");
         return std::vector<std::string>{"ingest", "--video", grid, "--workspace", (d / "file").string()};
       },
       2, {"is a file, not a folder"}},
      {"a workspace in use by another run",
       [](const fs::path& d) {
         // This test process holds the workspace's lock while the command runs.
         static int fd = -1;
         if (fd >= 0) ::close(fd);
         fd = ::open((d / "ws" / ".lock").c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
         EXPECT_EQ(::flock(fd, LOCK_EX | LOCK_NB), 0);
         return std::vector<std::string>{"track", "--workspace", (d / "ws").string()};
       },
       2, {"in use by another headforge process"}, true},
      {"pack without --out",
       [](const fs::path& d) { return std::vector<std::string>{"pack", "--workspace", (d / "ws").string()}; }, 2,
       {"--out"}, true},
  };
}

// The inputs (exit 1): the video and what ingest reads with it.
std::vector<BadInput> VideoInputCases() {
  const auto video = IngestArgs;
  const std::string grid = (kGrid / "bbaf2n.mpg").string();
  return {
      {"a missing video", [=](const fs::path& d) { return video(d, {"--video", (d / "none.mp4").string()}); }, 1,
       {"not found", "none.mp4"}},
      {"a missing matte model",
       [=](const fs::path& d) {
         fs::create_directories(d / "models");
         return video(d, {"--video", grid, "--matte", "rvm", "--vision-models", (d / "models").string()});
       },
       1, {"rvm.json", "is missing", "install_deps.sh"}},
      {"a damaged matte model",
       [=](const fs::path& d) {
         fs::create_directories(d / "models");
         WriteText(d / "models" / "rvm.json", "{\"modelTopology\": {\"node\": [");
         return video(d, {"--video", grid, "--matte", "rvm", "--vision-models", (d / "models").string()});
       },
       1, {"rvm.json"}},
      {"an empty video file",
       [=](const fs::path& d) {
         WriteText(d / "empty.mp4", "");
         return video(d, {"--video", (d / "empty.mp4").string()});
       },
       1, {"empty.mp4", "is empty"}},
      {"a text file named .mp4",
       [=](const fs::path& d) {
         WriteText(d / "notes.mp4", "not a video\n");
         return video(d, {"--video", (d / "notes.mp4").string()});
       },
       1, {"notes.mp4", "does not recognise it as a video"}},
      {"an audio-only file",
       [=](const fs::path& d) {
         EXPECT_EQ(std::system(("ffmpeg -loglevel error -y -f lavfi -i sine=frequency=440:duration=1 '" +
                                (d / "speech.m4a").string() + "'")
                                   .c_str()),
                   0);
         return video(d, {"--video", (d / "speech.m4a").string()});
       },
       1, {"speech.m4a", "no video stream"}},
      {"a video truncated before its first frame",
       [=](const fs::path& d) {
         std::string bytes;
         EXPECT_TRUE(ReadFileToString(kGrid / "bbaf2n.mpg", &bytes).ok());
         WriteText(d / "cut.mpg", bytes.substr(0, 2048));
         return video(d, {"--video", (d / "cut.mpg").string()});
       },
       1, {"cut.mpg", "damaged or truncated"}},
      {"an MP4 cut off before its index (moov atom)",
       [=](const fs::path& d) {
         EXPECT_EQ(std::system(("ffmpeg -loglevel error -y -i '" + grid + "' -t 1 -an '" + (d / "whole.mp4").string() +
                                "'")
                                   .c_str()),
                   0);
         std::string bytes;
         EXPECT_TRUE(ReadFileToString(d / "whole.mp4", &bytes).ok());
         WriteText(d / "cut.mp4", bytes.substr(0, bytes.size() / 2));  // the index is written last
         return video(d, {"--video", (d / "cut.mp4").string()});
       },
       1, {"cut.mp4", "does not recognise it as a video"}},
      {"a folder without images",
       [=](const fs::path& d) {
         fs::create_directories(d / "empty_folder");
         WriteText(d / "empty_folder" / "readme.txt", "x");
         return video(d, {"--video", (d / "empty_folder").string()});
       },
       1, {"holds no images"}},
      {"a capture's folder instead of its cameras' folders",
       [=](const fs::path& d) {
         for (const char* cam : {"cam0", "cam1"}) {
           fs::create_directories(d / "capture" / cam);
           cv::imwrite((d / "capture" / cam / "000000.png").string(), cv::Mat(64, 64, CV_8UC3, cv::Scalar(40, 80, 120)));
         }
         return video(d, {"--video", (d / "capture").string()});
       },
       1, {"holds no images, but 2 of its folders do: give one folder per camera, --video", "capture/cam0",
           "capture/cam1"}},
      {"a folder of images of two sizes",
       [=](const fs::path& d) {
         fs::create_directories(d / "mixed");
         cv::imwrite((d / "mixed" / "a.png").string(), cv::Mat(64, 64, CV_8UC3, cv::Scalar(40, 80, 120)));
         cv::imwrite((d / "mixed" / "b.png").string(), cv::Mat(48, 64, CV_8UC3, cv::Scalar(40, 80, 120)));
         return video(d, {"--video", (d / "mixed").string()});
       },
       1, {"b.png", "differs in size"}},
      {"a video without a face",
       [=](const fs::path& d) {
         cv::theRNG().state = 11;
         WriteVideo(d / "noise.avi", 8, cv::Size(320, 240), [](int) {
           cv::Mat frame(240, 320, CV_8UC3);
           cv::randu(frame, cv::Scalar::all(0), cv::Scalar::all(255));
           return frame;
         });
         return video(d, {"--video", (d / "noise.avi").string()});
       },
       1, {"no face found", "noise.avi"}},
      {"a face of 20 px",
       [=](const fs::path& d) {
         WriteGridFrames(d / "tiny.avi", 8, 0.12);
         return video(d, {"--video", (d / "tiny.avi").string()});
       },
       1, {"tiny.avi", "px", "too small", "--min-face"}},
  };
}

// The inputs (exit 1): the data, the face model, a workspace's files and
// what training needs.
std::vector<BadInput> WorkspaceInputCases() {
  const auto video = IngestArgs;
  const std::string grid = (kGrid / "bbaf2n.mpg").string();
  return {
      {"a missing data folder",
       [=](const fs::path& d) { return video(d, {"--video", grid, "--data", (d / "nowhere").string()}); }, 1,
       {"UltraFace model not found", "--data"}},
      {"a missing face model",
       [](const fs::path& d) {
         return std::vector<std::string>{"track", "--workspace", (d / "ws").string(), "--face-model",
                                         (d / "none.h5").string()};
       },
       1, {"no face model at", "--face-model"}, true},
      {"no workspace to show",
       [](const fs::path& d) { return std::vector<std::string>{"status", (d / "nothing").string()}; }, 1,
       {"no workspace at"}},
      {"render before train",
       [](const fs::path& d) { return std::vector<std::string>{"render", "--workspace", (d / "ws").string()}; }, 1,
       {"run headforge train first"}, true},
      {"export of a model never trained",
       [](const fs::path& d) {
         return std::vector<std::string>{"export", "--workspace", (d / "ws").string(), "--formats", "gaussians"};
       },
       1, {"no trained avatar", "run headforge train first"}, true},
      {"tracking.json that is not JSON",
       [](const fs::path& d) {
         WriteText(d / "ws" / "tracking.json", "{ \"version\": 1, \"frames\": [");
         return std::vector<std::string>{"train", "--workspace", (d / "ws").string(), "--steps", "5"};
       },
       1, {"tracking.json is not valid JSON", "run headforge track again"}, true},
      {"a NaN in tracking.json",
       [](const fs::path& d) {
         // JSON has no NaN: a writer that meets one writes null.
         EditJson(d / "ws" / "tracking.json",
                  [](nlohmann::json* j) { (*j)["frames"][3]["expression"]["jawOpen"] = nullptr; });
         return std::vector<std::string>{"train", "--workspace", (d / "ws").string(), "--steps", "5"};
       },
       1, {"tracking.json", "frame 3", "run headforge track again"}, true},
      {"cameras_head.json of another version",
       [](const fs::path& d) {
         EditJson(d / "ws" / "cameras_head.json", [](nlohmann::json* j) { (*j)["version"] = 99; });
         return std::vector<std::string>{"train", "--workspace", (d / "ws").string(), "--steps", "5"};
       },
       1, {"cameras_head.json has version 99", "newer HeadForge", "run headforge align again"}, true},
      {"a capture too short to train on",
       [=](const fs::path& d) {
         WriteGridFrames(d / "short.avi", 6, 1.0);
         return std::vector<std::string>{"run", "--video", (d / "short.avi").string(), "--workspace",
                                         (d / "w").string(), "--until", "train", "--steps", "5"};
       },
       1, {"6 frames", "at least", "longer video"}},
  };
}

// The inputs (exit 1).
std::vector<BadInput> InputCases() {
  std::vector<BadInput> cases = VideoInputCases();
  for (BadInput& input : WorkspaceInputCases()) cases.push_back(std::move(input));
  return cases;
}

std::vector<BadInput> Table() {
  std::vector<BadInput> table = CommandLineCases();
  for (BadInput& input : InputCases()) table.push_back(std::move(input));
  return table;
}

class BadInputs : public ::testing::TestWithParam<size_t> {};

TEST_P(BadInputs, SayWhatHappenedAndWhatToTryAndLoseNothing) {
  const BadInput bad = Table()[GetParam()];
  std::string id;
  for (char c : bad.name) id += std::isalnum(static_cast<unsigned char>(c)) ? c : '_';
  const fs::path dir = fs::temp_directory_path() / ("hf_bad_" + id);
  fs::remove_all(dir);
  fs::create_directories(dir);
  if (bad.on_workspace) CopyOf(TrackedTalkingStatic(), dir / "ws");
  const std::vector<std::string> args = bad.make(dir);
  // What is in the workspace, the case's own damage included, stays.
  std::map<std::string, std::string> before;
  if (bad.on_workspace) before = Snapshot(dir / "ws");
  const Result r = Headforge(args);
  EXPECT_EQ(r.code, bad.code) << bad.name << "\n" << r.err;
  const std::vector<std::string> lines = ReasonLines(r.err);
  ASSERT_EQ(lines.size(), 1u) << bad.name << ": one line saying why, not:\n" << r.err;
  // Nor does ffmpeg add its own ("[mov,mp4,... @ 0x55…] moov atom not found").
  EXPECT_EQ(r.err.find(" @ 0x"), std::string::npos) << bad.name << ": ffmpeg's own lines reached stderr:\n" << r.err;
  for (const std::string& part : bad.says)
    EXPECT_NE(lines[0].find(part), std::string::npos) << bad.name << ": '" << part << "' not in\n" << lines[0];
  if (bad.on_workspace) {
    EXPECT_EQ(Snapshot(dir / "ws"), before) << bad.name << ": the workspace changed";
  }
  fs::remove_all(dir);
}

INSTANTIATE_TEST_SUITE_P(Table, BadInputs, ::testing::Range<size_t>(0, Table().size()),
                         [](const ::testing::TestParamInfo<size_t>& info) {
                           const std::string name = Table()[info.param].name;
                           std::string id;
                           for (char c : name)
                             if (std::isalnum(static_cast<unsigned char>(c))) id += c;
                           return id;
                         });

// Accepted with a warning: a video damaged after its first frames is
// ingested as far as it decodes, and the damage is said in the log, in the
// stage's summary and in capture.json.
// Accepted with a warning: without the learned models, ingest's --matte auto
// says so once and masks with GrabCut (capture.json says which).
TEST(BadInputsAccepted, WithoutTheMatteModelsIngestMasksWithGrabCut) {
  const fs::path dir = fs::temp_directory_path() / "hf_bad_no_models";
  fs::remove_all(dir);
  fs::create_directories(dir / "models");
  const Result r = Headforge({"ingest", "--video", (kGrid / "bbaf2n.mpg").string(), "--max-frames", "12", "--matte",
                              "auto", "--vision-models", (dir / "models").string(), "--workspace",
                              (dir / "w").string()});
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_NE(r.err.find("install_deps.sh"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("masking with GrabCut instead"), std::string::npos) << r.err;
  nlohmann::json capture;
  ASSERT_TRUE(ReadJson(dir / "w" / "capture.json", &capture).ok());
  EXPECT_EQ(capture["cameras"][0]["masks"], "grabcut");
  fs::remove_all(dir);
}

// An MP4 whose index sits at its start (faststart) and whose data was cut
// short: the container still declares every frame, the stream ends early.
// Ingest says both counts, and the workspace records the damage.
TEST(BadInputsAccepted, AVideoCutShortSaysTheFramesItGotAndTheFramesDeclared) {
  const fs::path dir = fs::temp_directory_path() / "hf_bad_cut_short";
  fs::remove_all(dir);
  fs::create_directories(dir);
  ASSERT_EQ(std::system(("ffmpeg -loglevel error -y -i '" + (kGrid / "bbaf2n.mpg").string() +
                         "' -an -c:v libx264 -movflags +faststart '" + (dir / "whole.mp4").string() + "'")
                            .c_str()),
            0);
  std::string bytes;
  ASSERT_TRUE(ReadFileToString(dir / "whole.mp4", &bytes).ok());
  WriteText(dir / "cut.mp4", bytes.substr(0, bytes.size() * 2 / 5));
  const Result r = Headforge({"ingest", "--video", (dir / "cut.mp4").string(), "--workspace", (dir / "w").string(),
                              "--frame-size", "128", "--threads", "1"});
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_NE(r.err.find("where its container declares 75"), std::string::npos) << r.err;
  nlohmann::json capture, manifest;
  ASSERT_TRUE(ReadJson(dir / "w" / "capture.json", &capture).ok());
  const size_t frames = capture["cameras"][0]["frames"].size();
  EXPECT_GT(frames, 5u);
  EXPECT_LT(frames, 60u);
  ASSERT_TRUE(ReadJson(dir / "w" / "workspace.json", &manifest).ok());
  EXPECT_NE(manifest.dump().find("the video ended after"), std::string::npos) << manifest.dump();
  // The whole file: no such note.
  const Result whole = Headforge({"ingest", "--video", (dir / "whole.mp4").string(), "--workspace",
                                  (dir / "w2").string(), "--frame-size", "128", "--threads", "1"});
  ASSERT_EQ(whole.code, 0) << whole.err;
  EXPECT_EQ(whole.err.find("container declares"), std::string::npos) << whole.err;
  fs::remove_all(dir);
}

TEST(BadInputsAccepted, ATruncatedVideoIsIngestedAndTheDamageSaid) {
  const fs::path dir = fs::temp_directory_path() / "hf_bad_truncated";
  fs::remove_all(dir);
  fs::create_directories(dir);
  std::string bytes;
  ASSERT_TRUE(ReadFileToString(kGrid / "bbaf2n.mpg", &bytes).ok());
  WriteText(dir / "cut.mpg", bytes.substr(0, 20000));
  const Result r = Headforge({"ingest", "--video", (dir / "cut.mpg").string(), "--workspace", (dir / "w").string()});
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_NE(r.err.find("damaged or truncated"), std::string::npos) << r.err;
  nlohmann::json capture, manifest;
  ASSERT_TRUE(ReadJson(dir / "w" / "capture.json", &capture).ok());
  EXPECT_GT(capture["cameras"][0].value("decoder_errors", 0), 0);
  ASSERT_TRUE(ReadJson(dir / "w" / "workspace.json", &manifest).ok());
  EXPECT_NE(manifest.dump().find("DAMAGED INPUT"), std::string::npos);
  // Too few frames to train on: `run` stops after ingest (up to date) and
  // says so, before calibrate and track spend their time on them.
  const int frames = int(capture["cameras"][0]["frames"].size());
  ASSERT_LT(frames, 8);
  const Result run = Headforge({"run", "--video", (dir / "cut.mpg").string(), "--workspace", (dir / "w").string()});
  EXPECT_NE(run.code, 0);
  EXPECT_NE(run.err.find("run: stopped after ingest: train: ingest made " + std::to_string(frames) + " frame"),
            std::string::npos)
      << run.err;
  EXPECT_NE(run.err.find("--until track"), std::string::npos) << run.err;
  ASSERT_TRUE(ReadJson(dir / "w" / "workspace.json", &manifest).ok());
  for (const auto& stage : manifest["stages"]) EXPECT_NE(stage["name"], "calibrate") << manifest.dump();
  // The whole clip is not.
  const Result whole = Headforge({"ingest", "--video", (kGrid / "bbaf2n.mpg").string(), "--workspace",
                                  (dir / "whole").string()});
  ASSERT_EQ(whole.code, 0) << whole.err;
  EXPECT_EQ(whole.err.find("damaged"), std::string::npos) << whole.err;
  fs::remove_all(dir);
}

}  // namespace
}  // namespace headforge
