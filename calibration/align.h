// The align stage: the similarity head_from_world that takes the
// reconstruction's world frame to the face model's metric head frame.
// Landmarks are triangulated from every registered view (DLT, then Ceres with
// a robust loss) and matched to the model's landmark vertices by Umeyama's
// method inside RANSAC over the rigid landmarks. Residuals are in millimetres.
#pragma once

#include <vector>

#include "core/camera_set.h"
#include "calibration/landmark_embedding.h"
#include "calibration/mesh_embedding.h"
#include "calibration/similarity.h"
#include "capture/capture_io.h"
#include "core/face_model.h"
#include "core/options.h"

namespace headforge {

struct AlignOptions {
  double inlier_mm = 8.0;      // RANSAC inlier threshold, millimetres
  double max_reprojection_px = 8.0;  // triangulated landmarks reprojecting worse are dropped
  double max_yaw_deg = 35.0;         // views of a more turned head give no landmarks
  // Which views' head poses give the rotation (method "views"): "geometry"
  // starts from the views whose own PnP yaw is within max_yaw_deg, then
  // chooses the views whose cameras face the face within max_yaw_deg and
  // max_elevation_deg under the rotation so far, until the choice settles;
  // "pnp" keeps the first choice.
  std::string select_views = "geometry";
  double max_elevation_deg = 30.0;
  // "views": the rotation from the views' PnP head poses (robust chordal mean),
  // scale and translation from the triangulated landmarks with that rotation
  // held; "landmarks": Umeyama in RANSAC on the triangulated landmarks alone.
  std::string method = "views";
  // The detector's landmarks on the model (landmark_embedding.h); "" for the model's vertices.
  std::string landmark_embedding = DefaultLandmarkEmbedding();
  // "reprojection": with the rotation held, refine scale and translation by
  // the reprojection of the model's landmarks into every view used; "off":
  // keep the fit to the triangulated landmarks.
  std::string refine = "reprojection";
  double refine_robust_px = 2.0;  // Huber scale of that refinement
  // "points": fit the face model's surface, with the subject's identity, to
  // the points triangulated on the face (face_points.h), and take the head
  // frame's rotation, translation and scale from it (surface_fit.h): one
  // camera moving round a still head from all its frames; several cameras
  // from each instant's views, each instant with its own head pose in the
  // fit. "off": keep the landmarks'.
  std::string surface = "points";
  double surface_noise_mm = 1.0;  // the points' noise in that fit (SurfaceFitOptions)
  // Several cameras (a rig): the surface fit runs only when asked. It takes
  // the head frame nearer the truth (dome_360 2.30 -> 0.52 deg) but the
  // dome's avatar trained on it scored lower (docs/benchmarks/capture_360.md).
  bool rig_surface = false;
  int surface_instants = 60;      // several cameras: the instants the fit uses at most
  // World-frame cameras: fail when the triangulated landmarks miss the model by
  // more than this median (mm), a sign of a broken reconstruction.
  double max_residual_mm = 40.0;
  // Several cameras watching the head (a rig): where a view's frame has the
  // face mesh (468 points, ingest's FaceMesh), its head pose comes from
  // them ("mesh"): the 68-point predictor reads a turned face as nearly
  // frontal, the mesh network far less. "landmarks": from the 68 points.
  std::string rig_view_poses = "mesh";
  std::string mesh_embedding = DefaultMeshEmbedding();  // the mesh's points on the model
  // World-frame cameras: leave out the views FindMisplacedViews finds (more
  // than half of them: fail).
  bool drop_misplaced = true;
  Status Check() const;
};
void AddAlignOptions(OptionSet* options, AlignOptions* align);

// A view whose frame shows the head (its head mask covers over 1% of the
// frame) but whose pose in the head frame puts the head's centre behind the
// camera, or more than a quarter of the frame outside it: calibrate placed
// it wrong (COLMAP matching a back camera's room to the wrong side of a
// dome, say). Views without a mask file, or whose mask is nearly empty, are
// not judged.
struct MisplacedView {
  std::string camera;
  int frame = 0;
  bool behind = false;  // the head behind the camera (else outside its frame)
};
Status FindMisplacedViews(const IngestedCapture& capture, const CameraSet& head_cameras,
                          std::vector<MisplacedView>* misplaced);

struct AlignResult {
  Sim3 head_from_world;
  SimilarityQuality quality = SimilarityQuality::kGood;
  std::string method;                  // views or landmarks
  std::vector<int> landmarks_used;     // iBUG indices triangulated and used
  std::vector<Eigen::Vector3d> points;  // per used landmark: triangulated, world frame
  std::vector<double> residuals_mm;    // per used landmark, after alignment
  std::vector<bool> inlier;
  double rms_mm = 0.0, median_mm = 0.0;
  int reference_frame = -1;            // several cameras: the frame whose head pose defines the head frame
  int views_used = 0;                  // views whose head poses gave the rotation (method views)
  double reprojection_median_px = 0.0;  // landmark reprojection after the refinement (0: not refined)
  Sim3 landmarks_head_from_world;  // before the surface fit (head_from_world when it did not run)
  // The surface fit (surface_points 0: not run; surface_note says why).
  int face_points = 0;     // points triangulated on the face
  int surface_points = 0;  // of those, paired with the surface in the fit's last round
  double surface_median_mm = 0, surface_turn_deg = 0, surface_scale_change = 0;
  std::string surface_note;
  CameraSet cameras;                   // the views re-expressed in the head frame
  std::vector<MisplacedView> misplaced;  // views left out of `cameras` (AlignOptions::drop_misplaced)
  std::string message;
};

// Aligns `cameras` (frame "world"). For head-pose cameras (frame "head") the
// transform is the identity and the residuals of the triangulated landmarks
// against the model are still reported. The surface fit reads the frames.
Status RunAlign(const AlignOptions& options, const IngestedCapture& capture, const CameraSet& cameras,
                const FaceModel& model, AlignResult* result);

// Re-expresses cameras through a similarity: cam_from_head = cam_from_world * world_from_head,
// with the translation rescaled so that the head frame stays metric.
CameraSet ToHeadFrame(const CameraSet& cameras, const Sim3& head_from_world);

// alignment.json: everything above but the per-landmark points, the
// landmarks' own frame and the cameras (which are cameras_head.json).
constexpr int kAlignmentVersion = 1;
Status WriteAlignment(const AlignResult& result, const fs::path& path);
// Reads what WriteAlignment wrote (checking its version) into `result`.
Status ReadAlignment(const fs::path& path, AlignResult* result);

}  // namespace headforge
