// 3D points on the face, triangulated from pairs of registered views of one
// camera moving round a still head (or of a rig's cameras at one instant): SIFT features inside each frame's face
// (the landmarks' outline, grown by a margin), matched between views that see
// the face from directions a few to some tens of degrees apart, and
// triangulated with the calibrated cameras. Structure from motion spends its
// features on the whole frame and keeps some hundreds on the skin; this keeps
// the faint ones on the face and gives thousands, for align's surface fit.
#pragma once

#include <vector>

#include <Eigen/Core>

#include "core/camera_set.h"
#include "capture/capture_io.h"
#include "core/status.h"

namespace headforge {

struct FacePointOptions {
  // SIFT's contrast threshold. OpenCV's default (0.04) finds a few dozen
  // features on a face; skin's faint texture needs a lower one.
  double contrast_threshold = 0.003;
  double ratio = 0.8;  // Lowe's ratio test on the descriptor distances
  // Each view is matched with up to `partners` others whose optical axes lie
  // between min_angle_deg and max_angle_deg from its own, nearest first.
  int partners = 8;
  double min_angle_deg = 3.0, max_angle_deg = 40.0;
  double max_reprojection_px = 1.0;  // in both views
  double margin_px = 7.0;            // the landmarks' convex hull grown by this
};

struct FacePointStats {
  int views = 0;   // registered views with landmarks
  int pairs = 0;   // view pairs matched
  int points = 0;  // points triangulated
};

// One view of the capture: a camera's frame.
struct FaceViewRef {
  std::string camera;
  int frame = 0;
};

// The points of `camera`'s registered views (frame "world"), in the world
// frame. Views without landmarks are left out. Fails when a frame cannot be
// read or the camera has no intrinsics.
Status TriangulateFacePoints(const IngestedCapture& capture, const CameraSet& cameras, const std::string& camera,
                             const FacePointOptions& options, std::vector<Eigen::Vector3d>* points,
                             FacePointStats* stats);

// The same from the given views, of any cameras: a rig's views of one
// instant, which see one face from several directions at once. Views not
// registered, without landmarks or unknown to the capture are left out.
Status TriangulateFacePoints(const IngestedCapture& capture, const CameraSet& cameras,
                             const std::vector<FaceViewRef>& views, const FacePointOptions& options,
                             std::vector<Eigen::Vector3d>* points, FacePointStats* stats);

}  // namespace headforge
