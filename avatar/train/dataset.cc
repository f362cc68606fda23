#include "avatar/train/dataset.h"

#include <torch/torch.h>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>

#include <Eigen/Geometry>

#include "avatar/train/hull_masks.h"
#include "avatar/train/tensor_image.h"
#include "capture/capture_io.h"
#include "core/camera_set.h"
#include "core/mesh_renderer.h"
#include "core/options.h"
#include "reconstruction/tracking_io.h"

namespace headforge {
namespace {

// The frame and its mask, lens distortion removed, resized to `size`.
Status ReadView(const IngestedCapture& capture, const IngestedCamera& cam, const CameraIntrinsics& lens, int frame,
                cv::Size size, cv::Mat* image, cv::Mat* mask) {
  HF_RETURN_IF_ERROR(ReadUndistortedFrame(capture, cam.name, lens, frame, image, mask));
  if (image->size() != size) {
    cv::resize(*image, *image, size, 0, 0, cv::INTER_AREA);
    cv::resize(*mask, *mask, size, 0, 0, cv::INTER_AREA);
  }
  return Status::Ok();
}

// Boxes round the eyes and the mouth, grown by a third and at least 6 px.
void RegionBoxes(const Landmarks68& points, const CameraIntrinsics& lens, double scale, AvatarView* view) {
  const std::array<std::pair<int, int>, 3> ranges = {{{36, 41}, {42, 47}, {48, 67}}};
  for (size_t r = 0; r < 3; ++r) {
    double x0 = 1e30, y0 = 1e30, x1 = -1e30, y1 = -1e30;
    for (int i = ranges[r].first; i <= ranges[r].second; ++i) {
      const Eigen::Vector2d p = lens.Undistort(Eigen::Vector2d(points[i].x, points[i].y));
      const double x = (p.x() + 0.5) * scale - 0.5, y = (p.y() + 0.5) * scale - 0.5;
      x0 = std::min(x0, x), y0 = std::min(y0, y), x1 = std::max(x1, x), y1 = std::max(y1, y);
    }
    const double grow_x = std::max(3.0, (x1 - x0) / 6), grow_y = std::max(3.0, (y1 - y0) / 6);
    view->regions[r] = {float(x0 - grow_x), float(y0 - grow_y), float(x1 + grow_x), float(y1 + grow_y)};
  }
  view->has_landmarks = true;
}

// The tracked mesh of `vertices` [V, 3] drawn through `camera` on its square
// canvas of `side` px: u, v (the model's UV range scaled to 0..255) and
// covered (255) per pixel, uint8 [3, side, side]. A model without UVs gets the
// neutral shape's x and y in their place.
torch::Tensor RenderUvMap(const FaceModel& model, const torch::Tensor& vertices, const torch::Tensor& identity,
                          const SplatCamera& camera, int side) {
  const SquareCanvas canvas = MakeSquareCanvas(camera, side);
  const torch::Tensor v = vertices.to(torch::kFloat32).contiguous();
  Mesh mesh;
  mesh.vertices = Eigen::Map<const Eigen::Matrix3Xf>(v.data_ptr<float>(), 3, v.size(0));
  mesh.triangles = model.triangles();
  const auto unit = [](const Eigen::Matrix2Xf& uv) -> Eigen::Matrix2Xf {
    const Eigen::Vector2f lo = uv.rowwise().minCoeff(), hi = uv.rowwise().maxCoeff();
    return ((uv.colwise() - lo).array().colwise() / (hi - lo).array().max(1e-6f)).matrix();
  };
  if (model.has_uv() && model.uv_triangles().cols() == mesh.triangles.cols()) {
    mesh.uvs = unit(model.uv_coords());
    mesh.uv_triangles = model.uv_triangles();
  } else {
    const torch::Tensor neutral = identity.to(torch::kFloat32).contiguous();
    mesh.uvs = unit(Eigen::Map<const Eigen::Matrix3Xf>(neutral.data_ptr<float>(), 3, neutral.size(0)).topRows(2));
  }
  mesh.materials.emplace_back();
  RenderOptions render;
  render.supersample = 1;
  RenderOutput out;
  RenderMeshes({&mesh}, ToPinholeCamera(canvas.camera), render, &out);
  torch::Tensor map = torch::zeros({3, side, side}, torch::kUInt8);
  auto a = map.accessor<uint8_t, 3>();
  for (int y = 0; y < side; ++y)
    for (int x = 0; x < side; ++x) {
      if (out.triangle.at<int32_t>(y, x) < 0) continue;
      const cv::Vec2f uv = out.uv.at<cv::Vec2f>(y, x);
      a[0][y][x] = uint8_t(std::lround(std::clamp(uv[0], 0.f, 1.f) * 255));
      a[1][y][x] = uint8_t(std::lround(std::clamp(uv[1], 0.f, 1.f) * 255));
      a[2][y][x] = 255;
    }
  return map;
}

// Where the mesh of `vertices` covers `camera`'s image: CV_8U, 255 on it.
cv::Mat MeshCoverage(const Eigen::Matrix3Xf& vertices, const Eigen::Matrix3Xi& triangles, const SplatCamera& camera) {
  Mesh mesh;
  mesh.vertices = vertices;
  mesh.triangles = triangles;
  mesh.materials.emplace_back();
  RenderOptions render;
  render.supersample = 1;
  render.threads = 1;
  RenderOutput out;
  RenderMeshes({&mesh}, ToPinholeCamera(camera), render, &out);
  return out.triangle >= 0;
}

// The angle (degrees) between the face's direction (+z in the head frame)
// and the way from the head's origin to the camera of `cam_from_canonical`.
double FaceAngleDeg(const Eigen::Isometry3d& cam_from_canonical) {
  const Eigen::Vector3d facing = cam_from_canonical.linear() * Eigen::Vector3d::UnitZ();
  const Eigen::Vector3d to_camera = -cam_from_canonical.translation().normalized();
  return std::acos(std::clamp(facing.dot(to_camera), -1.0, 1.0)) * 180.0 / M_PI;
}

// One camera carried round a still head: the expression every view carries,
// each weight's median over the tracked frames whose view faces the face
// (within the tracker's fitted yaw, 35 degrees), else over every frame the
// tracker fitted (not interpolated), else zero.
Eigen::VectorXf SharedExpression(const IngestedCapture& capture, const CameraSet& cameras,
                                 const TrackingFile& tracking, int* facing_frames) {
  std::vector<const TrackedFrame*> facing, fitted;
  for (const IngestedCamera& cam : capture.cameras)
    for (const IngestedFrame& f : cam.frames) {
      const CameraView* registered = cameras.FindView(cam.name, f.index);
      if (!registered || !registered->registered) continue;
      const TrackedFrame& tracked = tracking.frames[size_t(f.index)];
      if (tracked.interpolated) continue;
      fitted.push_back(&tracked);
      if (FaceAngleDeg(registered->cam_from_world * tracked.head_motion) <= 35.0) facing.push_back(&tracked);
    }
  *facing_frames = int(facing.size());
  const std::vector<const TrackedFrame*>& from = facing.empty() ? fitted : facing;
  const Eigen::Index n = Eigen::Index(tracking.expression_names.size());
  Eigen::VectorXf shared = Eigen::VectorXf::Zero(n);
  std::vector<double> values(from.size());
  for (Eigen::Index e = 0; e < n && !from.empty(); ++e) {
    for (size_t i = 0; i < from.size(); ++i) values[i] = from[i]->expression[e];
    std::nth_element(values.begin(), values.begin() + values.size() / 2, values.end());
    shared[e] = float(values[values.size() / 2]);
  }
  return shared;
}


Status CheckDatasetOptions(const DatasetOptions& options) {
  if (options.mask != "auto" && options.mask != "ingest" && options.mask != "mesh" && options.mask != "hull")
    return Status::InvalidArgument("--mask must be auto, ingest, mesh or hull, not '" + options.mask + "'");
  if (options.resolution < 16) return Status::InvalidArgument("the training resolution must be at least 16 pixels");
  if (options.holdout_order != "auto" && options.holdout_order != "last" && options.holdout_order != "interleaved")
    return Status::InvalidArgument("--holdout-order must be auto, last or interleaved, not '" + options.holdout_order +
                                   "'");
  return Status::Ok();
}

// The tracked subject's mesh: identity shape, expression basis, triangles
// and the model's named parts.
void SetSubjectMesh(const FaceModel& model, const TrackingFile& tracking, AvatarDataset* out) {
  out->expression_names = tracking.expression_names;
  const Eigen::Matrix3Xf identity = model.Identity(tracking.identity.cast<float>());
  out->identity_vertices = torch::from_blob(const_cast<float*>(identity.data()), {identity.cols(), 3}).clone();
  const Eigen::MatrixXf& basis = model.expression_basis();
  // Eigen is column-major: the transpose's buffer is the row-major [3V, E].
  const Eigen::MatrixXf basis_t = basis.transpose();
  out->expression_basis = torch::from_blob(const_cast<float*>(basis_t.data()), {basis.rows(), basis.cols()}).clone();
  const Eigen::Matrix3Xi& tris = model.triangles();
  out->triangles = torch::from_blob(const_cast<int*>(tris.data()), {tris.cols(), 3}, torch::kInt32).to(torch::kInt64);
  for (const auto& [name, region] : model.regions())
    out->mesh_parts[name] = {region.first_triangle, region.last_triangle};
}

// A view whose ingested mask is cut to its tracked mesh or that gets a UV
// map: done once every view's mesh is made (AttachViewVertices).
struct MeshWork {
  bool training;
  size_t index;  // in out.train or out.test
  cv::Mat mask;  // the ingested mask to cut; empty: no cut
  bool uv_map;
};

void CutToMeshes(const FaceModel& model, const DatasetOptions& options, const std::vector<MeshWork>& work,
                 AvatarDataset* out) {
  for (const MeshWork& w : work) {
    AvatarView& view = (w.training ? out->train : out->test)[w.index];
    if (!w.mask.empty())
      view.mask = MaskToTensor(MeshCutMask(w.mask, view.vertices, out->identity_vertices, out->triangles, view.view,
                                           options.mask_hair, options.mask_skin));
    if (w.uv_map)
      view.uv_map = RenderUvMap(model, view.vertices, out->identity_vertices, view.view, options.uv_map_side);
  }
}

// The hull's masks (--mask hull): the training views vote; every view's
// mask (`masks`, of the views `views` names as (training, index)) is remade.
Status AgreeOnHull(const std::vector<std::pair<bool, size_t>>& views, const std::vector<cv::Mat>& masks,
                   AvatarDataset* out) {
  std::vector<SplatCamera> cameras;
  std::vector<int> voters;
  for (size_t i = 0; i < views.size(); ++i) {
    const auto [training, index] = views[i];
    cameras.push_back((training ? out->train : out->test)[index].view);
    if (training) voters.push_back(int(i));
  }
  std::vector<cv::Mat> agreed;
  HF_RETURN_IF_ERROR(
      HullMasks(cameras, masks, voters, HullOptions(), &agreed, &out->hull_stats).WithContext("--mask hull"));
  for (size_t i = 0; i < views.size(); ++i) {
    const auto [training, index] = views[i];
    (training ? out->train : out->test)[index].mask = MaskToTensor(agreed[i]);
  }
  return Status::Ok();
}

}  // namespace

std::vector<int64_t> UsableTrainingViews(const AvatarDataset& data, std::string* note) {
  std::vector<int64_t> reliable, fitted;
  for (size_t i = 0; i < data.train.size(); ++i) {
    if (!data.train[i].unreliable) reliable.push_back(int64_t(i));
    if (!data.train[i].interpolated) fitted.push_back(int64_t(i));
  }
  note->clear();
  if (2 * reliable.size() >= data.train.size()) return reliable;
  *note = "the tracker flagged " + std::to_string(data.train.size() - reliable.size()) + " of " +
          std::to_string(data.train.size()) +
          " training views low-confidence or interpolated; training on the low-confidence ones too (only the " +
          std::to_string(data.train.size() - fitted.size()) + " interpolated left out)";
  return fitted;
}

cv::Mat MeshCutMask(const cv::Mat& mask, const torch::Tensor& vertices, const torch::Tensor& rest,
                    const torch::Tensor& triangles, const SplatCamera& camera, double hair, double skin) {
  const torch::Tensor v = vertices.to(torch::kFloat32).contiguous(), r = rest.to(torch::kFloat32).contiguous();
  const torch::Tensor t = triangles.to(torch::kInt32).contiguous();
  const Eigen::Matrix3Xf posed = Eigen::Map<const Eigen::Matrix3Xf>(v.data_ptr<float>(), 3, v.size(0));
  const Eigen::Map<const Eigen::Matrix3Xf> shape(r.data_ptr<float>(), 3, r.size(0));
  const Eigen::Matrix3Xi tris = Eigen::Map<const Eigen::Matrix3Xi>(t.data_ptr<int>(), 3, t.size(0));
  // Hair grows over the scalp: from 55% of the rest shape's height (the
  // brows) to its full allowance at 70%, in the head frame (+y up).
  const float low = shape.row(1).minCoeff(), high = shape.row(1).maxCoeff();
  const Eigen::Matrix3Xf normals = VertexNormals(posed, tris);
  Eigen::Matrix3Xf grown = posed;
  for (Eigen::Index i = 0; i < posed.cols(); ++i) {
    const float height = (shape(1, i) - low) / std::max(high - low, 1e-6f);
    const float scalp = std::clamp((height - 0.55f) / 0.15f, 0.f, 1.f);
    const float reach = float(skin) + scalp * float(std::max(0.0, hair - skin));
    grown.col(i) += reach * normals.col(i);
  }
  return cv::min(mask, MeshCoverage(grown, tris, camera));
}

Status LoadAvatarDataset(const fs::path& workspace, const FaceModel& model, const DatasetOptions& options,
                         AvatarDataset* dataset) {
  IngestedCapture capture;
  CameraSet cameras;
  TrackingFile tracking;
  HF_RETURN_IF_ERROR(ReadTrackedWorkspace(workspace, model, &capture, &cameras, &tracking));
  const int frames = capture.num_frames();
  HF_RETURN_IF_ERROR(CheckDatasetOptions(options));
  AvatarDataset out;
  out.num_frames = frames;
  const bool interleaved = HoldoutInterleaved(options.holdout_order, cameras.WalksRoundTheHead());
  const int held = HeldOutFrames(frames, options.holdout, interleaved);
  const HoldoutSplit split = SplitFrames(frames, options.holdout, interleaved);
  out.first_test_frame = split.first_test_frame;
  out.holdout_every = split.every;
  if (frames - held < options.min_train_frames)
    return Status::DataError("the capture has " + std::to_string(frames) + " frames: the model needs at least " +
                             std::to_string(options.min_train_frames) + " to train on besides the " +
                             std::to_string(held) + " held out; ingest a longer video");
  SetSubjectMesh(model, tracking, &out);
  // A still head that one camera goes round shows one state throughout.
  out.one_state = tracking.head_held_by_cameras && cameras.mode != "head-pose" && capture.cameras.size() == 1;
  Eigen::VectorXf shared_expression;
  if (out.one_state) shared_expression = SharedExpression(capture, cameras, tracking, &out.one_state_facing_views);
  out.mask = options.mask == "auto" ? (out.one_state ? "hull" : options.auto_mask) : options.mask;
  if (out.mask != "ingest" && out.mask != "mesh" && out.mask != "hull")
    return Status::InvalidArgument("--mask auto stands for '" + out.mask + "', which is no mask");
  if (out.mask == "hull" && !out.one_state)
    return Status::InvalidArgument("--mask hull makes the masks of one camera carried round a still head agree; "
                                   "this capture is not one (" + std::to_string(capture.cameras.size()) +
                                   " camera(s), head " + (tracking.head_held_by_cameras ? "held" : "moving") +
                                   "): give --mask ingest or mesh");
  const bool hull = options.images && out.mask == "hull";
  // The views' masks before the hull, each with where its view went.
  std::vector<cv::Mat> hull_masks;
  std::vector<std::pair<bool, size_t>> hull_views;  // (training, index)
  std::vector<MeshWork> mesh_work;

  // Names given one by one or comma-separated ("cam3,cam6").
  const std::vector<std::string> held_cameras = SplitCommaList(options.holdout_cameras);
  for (const std::string& name : held_cameras) {
    bool known = false;
    for (const IngestedCamera& cam : capture.cameras) known = known || cam.name == name;
    if (!known) return Status::InvalidArgument("no camera " + name + " to hold out (see capture.json's cameras)");
  }
  for (const IngestedCamera& cam : capture.cameras) {
    const bool held_camera =
        std::find(held_cameras.begin(), held_cameras.end(), cam.name) != held_cameras.end();
    const CameraIntrinsics* lens = cameras.FindCamera(cam.name);
    if (!lens) return Status::DataError("cameras_head.json has no camera " + cam.name + "; run headforge align again");
    const double scale = double(options.resolution) / std::max(cam.width, cam.height);
    const cv::Size size(int(std::lround(cam.width * scale)), int(std::lround(cam.height * scale)));
    for (const IngestedFrame& f : cam.frames) {
      const CameraView* registered = cameras.FindView(cam.name, f.index);
      if (!registered || !registered->registered) continue;
      const TrackedFrame& tracked = tracking.frames[size_t(f.index)];
      AvatarView view;
      view.frame = f.index;
      view.time_s = f.time_s;
      view.camera = cam.name;
      // One state for every view: no frame's own expression to be wrong.
      view.unreliable = !out.one_state && (tracked.interpolated || tracked.low_confidence);
      view.interpolated = !out.one_state && tracked.interpolated;
      cv::Mat image, mask;
      if (options.images) {
        HF_RETURN_IF_ERROR(ReadView(capture, cam, *lens, f.index, size, &image, &mask));
        view.image = ImageToTensor(image);
        view.mask = MaskToTensor(mask);
      }
      const Eigen::Isometry3d cam_from_canonical = registered->cam_from_world * tracked.head_motion;
      const Eigen::Isometry3d pose = cameras.mode == "head-pose" ? cam_from_canonical : tracked.head_motion;
      double rotation[9], translation[3];
      for (int i = 0; i < 3; ++i) {
        for (int j = 0; j < 3; ++j) rotation[3 * i + j] = pose.linear()(i, j);
        translation[i] = pose.translation()[i];
      }
      SetCameraPose(cam_from_canonical, &view.view);
      view.view.fx = lens->fx * scale;
      view.view.fy = (lens->fy > 0 ? lens->fy : lens->fx) * scale;
      view.view.cx = (lens->cx + 0.5) * scale - 0.5;
      view.view.cy = (lens->cy + 0.5) * scale - 0.5;
      view.view.width = size.width;
      view.view.height = size.height;
      view.face_angle_deg = FaceAngleDeg(cam_from_canonical);
      const Eigen::VectorXf expression = out.one_state ? shared_expression : tracked.expression.cast<float>();
      view.condition = torch::cat({torch::from_blob(const_cast<float*>(expression.data()), {expression.size()}).clone(),
                                   PoseCondition(rotation, translation)});
      const bool training = !out.HeldOut(f.index) && !held_camera;
      if (f.landmarks && view.face_angle_deg <= kLandmarkViewDeg) RegionBoxes(*f.landmarks, *lens, scale, &view);
      // The mask's cut and the UV map need the frame's tracked mesh: made
      // below, once the views' meshes are.
      const bool cut_mask = options.images && out.mask == "mesh";
      const bool uv_map = training && options.uv_map_side > 0;
      if (cut_mask || uv_map)
        mesh_work.push_back({training, (training ? out.train : out.test).size(), cut_mask ? mask : cv::Mat(), uv_map});
      if (hull) {
        hull_masks.push_back(mask);
        hull_views.emplace_back(training, (training ? out.train : out.test).size());
      }
      (training ? out.train : out.test).push_back(std::move(view));
      out.width = size.width;
      out.height = size.height;
    }
  }
  AttachViewVertices(&out);
  CutToMeshes(model, options, mesh_work, &out);
  if (hull) HF_RETURN_IF_ERROR(AgreeOnHull(hull_views, hull_masks, &out));
  if (int(out.train.size()) < options.min_train_frames)
    return Status::DataError("only " + std::to_string(out.train.size()) +
                             " registered views to train on (the model needs " + std::to_string(options.min_train_frames) +
                             "); calibrate registered too few frames");
  *dataset = std::move(out);
  return Status::Ok();
}

}  // namespace headforge
