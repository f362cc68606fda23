// How far a face model's identity modes can imitate a rigid motion of the
// face. A model built from scans aligned by Procrustes keeps some of the
// scans' pose spread in its identity modes: a combination of modes then moves
// the face almost as a small rotation, translation or scale would. A fit that
// estimates identity and head pose together cannot tell these apart beyond
// what is left over, so the left-over surface change per degree (or
// millimetre) says how accurately landmarks or surfaces must be measured for
// a head pose of a given accuracy.
#pragma once

#include <string>
#include <vector>

#include "core/face_model.h"
#include "core/status.h"

namespace headforge {

struct RigidImitation {
  std::string motion;         // "pitch (x)", ..., "scale"
  std::string unit;           // "1 deg", "1 mm", "1 %"
  double shared = 0.0;        // |B a (+ t)| / |d|: the part of the motion's displacement reproduced (0-1)
  double alpha_norm = 0.0;    // |a| of the least-squares imitation, per unit of motion
  double motion_mm = 0.0;     // rms displacement of the points under one unit of motion, mm
  double left_over_mm = 0.0;  // rms of what the modes cannot reproduce, mm
};

// Least-squares imitation, by the first `modes` identity modes, of each rigid
// motion (1 deg about the head's x, y, z axes through the points' centroid;
// 1 mm along them; 1% scale) on the model's points. Rotations and scale may
// also be imitated with a free translation (a fit moves the head as well, so
// the pivot does not matter); translations by the modes alone. Points:
// "landmarks" (its iBUG-68 vertices), "all", or the name of a region
// ("face"). InvalidArgument for an unknown set or a model without the modes.
Status ImitateRigidMotions(const FaceModel& model, int modes, const std::string& points,
                           std::vector<RigidImitation>* rows);

}  // namespace headforge
