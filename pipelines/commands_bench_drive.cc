// `headforge bench drive`: cross-identity driving measured. The avatar of
// one workspace is driven by other tracked workspaces (and by its own, the
// reference), once per remedy of the driver's weights (avatar/drive_remedy.h),
// on every Nth frame of each driver; each render is scored against the
// driving frame (the driver's own frame at that index) and against the
// avatar's own first frame (the camera the renders use):
// - F-LMD: the eyes' and mouth's landmarks of render and driving frame after
//   a similarity on their rigid points (AlignedExpressionDistance), percent
//   of the frame's eye-corner distance: does the avatar make the driver's
//   expression;
// - CSIM against the driving frame: for another driver a lower value is not
//   worse (the render should stay the avatar, not become the driver);
// - CSIM against the avatar's frame: does the avatar stay itself.
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <cmath>
#include <cstdio>

#include "avatar/avatar_render.h"
#include "avatar/face_metrics.h"
#include "capture/capture_io.h"
#include "core/log.h"
#include "core/paths.h"
#include "export/export.h"
#include "pipelines/commands.h"

namespace headforge {
namespace {

struct DriveRow {
  std::string driver, remedy;
  int frames = 0, scored = 0;             // rendered, and with a face found in render and driving frame
  double flmd = 0;                        // mean, percent of the eye-corner distance
  double flmd_error = 0;                  // its standard error over the frames
  std::vector<int> frame;                 // the frames scored, and each one's F-LMD and CSIMs
  std::vector<double> flmd_each, csim_driving_each, csim_avatar_each;
  double csim_driving = 0, csim_avatar = 0;
  double driver_to_avatar = 0;            // the driving frames' own CSIM against the avatar's frame
};

// A frame of a workspace at `size`, or empty.
cv::Mat FrameAt(const IngestedCapture& capture, int index, const cv::Size& size) {
  if (capture.cameras.empty()) return cv::Mat();
  cv::Mat image = cv::imread(capture.FramePath(capture.cameras.front().name, index).string(), cv::IMREAD_COLOR);
  if (!image.empty() && image.size() != size) cv::resize(image, image, size, 0, 0, cv::INTER_AREA);
  return image;
}

// The face of an image, its descriptor; false when there is none.
bool Describe(FaceMetrics& metrics, const cv::Mat& image, FaceMetrics::Face* face, std::vector<float>* descriptor) {
  if (image.empty() || !metrics.FindFace(image, face)) return false;
  *descriptor = metrics.Describe({FaceMetrics::Crop(image, face->square)}).front();
  return true;
}

// Renders the avatar driven by `driver` with `remedy` into `dir` and scores each render.
Status MeasureDriving(const std::string& workspace, const std::string& face_model, const std::string& driver,
                      const std::string& remedy, int every, const std::vector<float>& avatar_face,
                      FaceMetrics& metrics, const fs::path& dir, DriveRow* row) {
  IngestedCapture capture;
  HF_RETURN_IF_ERROR(ReadIngestedCapture(driver, &capture));
  AvatarRenderOptions render;
  render.drive = driver;
  render.drive_remedy = remedy;
  render.frames = {"0-" + std::to_string(capture.num_frames() - 1) + ":" + std::to_string(every)};
  NullProgress progress;
  AvatarRenderSummary summary;
  HF_RETURN_IF_ERROR(RenderAvatarFrames(workspace, face_model, render, dir, &progress, &summary));
  std::vector<int> frames;
  HF_RETURN_IF_ERROR(ParseFrameList(render.frames, capture.num_frames(), &frames));
  row->driver = fs::path(driver).filename().string();
  row->remedy = remedy;
  row->frames = int(frames.size());
  for (size_t i = 0; i < frames.size(); ++i) {
    const cv::Mat image = cv::imread((dir / RenderFileName(render, frames[i], int(i))).string(), cv::IMREAD_COLOR);
    if (image.empty()) return Status::IoError("bench drive: cannot read a render in " + dir.string());
    FaceMetrics::Face face, driving_face;
    std::vector<float> descriptor, driving_descriptor;
    if (!Describe(metrics, image, &face, &descriptor) ||
        !Describe(metrics, FrameAt(capture, frames[i], image.size()), &driving_face, &driving_descriptor))
      continue;
    row->frame.push_back(frames[i]);
    row->flmd_each.push_back(AlignedExpressionDistance(face.landmarks, driving_face.landmarks));
    row->csim_driving_each.push_back(DescriptorCosine(descriptor, driving_descriptor));
    row->csim_avatar_each.push_back(DescriptorCosine(descriptor, avatar_face));
    row->flmd += row->flmd_each.back();
    row->csim_driving += row->csim_driving_each.back();
    row->csim_avatar += row->csim_avatar_each.back();
    row->driver_to_avatar += DescriptorCosine(driving_descriptor, avatar_face);
    ++row->scored;
  }
  if (row->scored > 0)
    for (double* mean : {&row->flmd, &row->csim_driving, &row->csim_avatar, &row->driver_to_avatar})
      *mean /= row->scored;
  double squares = 0;
  for (double d : row->flmd_each) squares += (d - row->flmd) * (d - row->flmd);
  if (row->scored > 1) row->flmd_error = std::sqrt(squares / (row->scored - 1) / row->scored);
  return Status::Ok();
}

}  // namespace

int BenchDrive(const std::vector<std::string>& args) {
  OptionSet options;
  CommonOptions common;
  AddCommonOptions(&options, &common, /*with_workspace=*/true);
  std::vector<std::string> drivers, remedies = {"none", "relative", "relative+span"};
  std::string out, face_api = ExportOptions::kDefaultFaceApi;
  int every = 5;
  bool json = false;
  options.Add("bench.drivers", &drivers,
              "Tracked workspaces that drive the avatar; the avatar's own workspace among them is the "
              "self-reenactment reference.", "drivers");
  options.Add("bench.remedies", &remedies, "Remedies of the driver's weights (render --drive-remedy).", "remedies");
  options.Add("bench.every", &every, "Render every Nth frame of each driver.", "every");
  options.Add("bench.out", &out, "Folder for the renders (default: WORKSPACE/bench_drive).", "out");
  options.Add("bench.face_api", &face_api, "node_modules holding @vladmandic/face-api (the identity network).",
              "face-api");
  options.Add("bench.json", &json, "Print one JSON document instead of the table.", "json");
  const int parsed = ParseOrExit(
      &options, args, "headforge bench drive --workspace DIR --drivers WS1,WS2 [--remedies none,relative] [--every 5]",
      "Drives the avatar trained in the workspace by each driver's tracked expressions, once per\n"
      "remedy, on every Nth frame, and prints per driver and remedy: F-LMD of eyes and mouth\n"
      "against the driving frame after a similarity on the rigid landmarks (percent of the\n"
      "eye-corner distance), CSIM against the driving frame (for another person lower is not\n"
      "worse: the render should stay the avatar) and against the avatar's own first frame, and\n"
      "the driving frames' own CSIM against that frame (how far apart the two people are).");
  if (parsed >= 0) return parsed;
  if (Status s = common.Check(true); !s.ok()) return ReportFailure(s);
  drivers = SplitCommaList(drivers);
  remedies = SplitCommaList(remedies);
  if (drivers.empty() || every < 1)
    return ReportFailure(Status::InvalidArgument("bench drive: give --drivers, and --every of at least 1"));
  ApplyCommonOptions(common);
  if (json) SetLogLevel(LogLevel::kWarning);
  const fs::path root = out.empty() ? fs::path(common.workspace) / "bench_drive" : fs::path(out);
  FaceMetricsOptions metric_options;
  metric_options.face_api_models = fs::path(face_api) / "@vladmandic" / "face-api" / "model";
  metric_options.landmark_model = DefaultLandmarkModel();
  metric_options.ultraface_dir = (fs::path(common.data_dir) / "models" / "ultraface").string();
  std::unique_ptr<FaceMetrics> metrics;
  if (Status s = FaceMetrics::Load(metric_options, &metrics); !s.ok()) return ReportFailure(s);
  IngestedCapture own;
  if (Status s = ReadIngestedCapture(common.workspace, &own); !s.ok()) return ReportFailure(s);
  FaceMetrics::Face face;
  std::vector<float> avatar_face;
  const cv::Mat first = own.cameras.empty() ? cv::Mat() : cv::imread(own.FramePath(own.cameras[0].name, 0).string());
  if (!Describe(*metrics, first, &face, &avatar_face))
    return ReportFailure(Status::DataError("bench drive: no face in the avatar's first frame"));
  std::vector<DriveRow> rows;
  for (const std::string& driver : drivers)
    for (const std::string& remedy : remedies) {
      DriveRow row;
      const fs::path dir = root / fs::path(driver).filename() / remedy;
      if (Status s = MeasureDriving(common.workspace, common.Settings().face_model, driver, remedy, every,
                                    avatar_face, *metrics, dir, &row);
          !s.ok())
        return ReportFailure(s.WithContext("bench drive"));
      HF_LOG(Info) << "bench drive: " << row.driver << ", " << remedy << ": F-LMD " << row.flmd << ", CSIM "
                   << row.csim_driving << " / " << row.csim_avatar;
      rows.push_back(row);
    }
  if (json) {
    nlohmann::json doc = nlohmann::json::array();
    for (const DriveRow& r : rows)
      doc.push_back({{"driver", r.driver}, {"remedy", r.remedy}, {"frames", r.frames}, {"scored", r.scored},
                     {"flmd_percent_eyes", r.flmd}, {"flmd_standard_error", r.flmd_error},
                     {"csim_driving", r.csim_driving},
                     {"csim_avatar", r.csim_avatar}, {"driving_csim_avatar", r.driver_to_avatar},
                     {"per_frame", {{"frame", r.frame}, {"flmd", r.flmd_each}, {"csim_driving", r.csim_driving_each},
                                    {"csim_avatar", r.csim_avatar_each}}}});
    std::printf("%s\n", doc.dump(1).c_str());
    return kExitOk;
  }
  std::printf("| driver | remedy | scored | F-LMD vs driving (%% eye dist., ± s.e.) | CSIM vs driving | CSIM vs avatar | "
              "driving frames' CSIM vs avatar |\n|---|---|---|---|---|---|---|\n");
  for (const DriveRow& r : rows)
    std::printf("| %s | %s | %d of %d | %.2f ± %.2f | %.3f | %.3f | %.3f |\n", r.driver.c_str(), r.remedy.c_str(),
                r.scored, r.frames, r.flmd, r.flmd_error, r.csim_driving, r.csim_avatar, r.driver_to_avatar);
  return kExitOk;
}

}  // namespace headforge
