// A long recording's frames chosen for what they show rather than when they
// were taken (ingest's --select).
#pragma once

#include <cstddef>
#include <vector>

#include "capture/face_choice.h"

namespace headforge {

struct CoverageSelection {
  std::vector<size_t> chosen;  // indices into the frames, ascending
  size_t groups = 0;           // k-means groups of landmark shapes (0: chosen evenly in time)
  size_t without_face = 0;     // frames where the followed face is not seen
  bool round_the_head = false; // a quarter or more without the face: chosen evenly in time
};

// At most `budget` of `frames` (one camera's, in time order), given the
// face followed in each (`faces`, SelectFaces' choice; nullptr where none).
// Each frame's 68 landmarks are brought by a similarity onto their mean
// shape: what is left is the head's turn and the expression. k-means
// (k-means++ seeding from `seed`, ten Lloyd iterations) groups these into
// `budget` groups; each group gives its sharpest frame among the half
// nearest its centre, so a pose or expression held for a long time gets no
// more frames than a brief one, and a blurred or mis-detected frame is not
// what represents its group. Frames without the face fill the budget last,
// spread in time. When a quarter or more of the frames show no face (a
// camera going round the head) the frames are chosen evenly in time.
CoverageSelection SelectForCoverage(const std::vector<const FrameAnalysis*>& frames,
                                    const std::vector<const FaceCandidate*>& faces, int budget, int seed);

}  // namespace headforge
