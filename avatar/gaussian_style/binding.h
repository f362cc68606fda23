// Gaussians riding on a triangle mesh, the way GaussianAvatars (Qian et al.
// 2024) binds them: each Gaussian belongs to a triangle, and its position,
// rotation and scale are kept in that triangle's frame (origin the centroid,
// x along the first edge, z the normal, one unit the mean edge length), so
// the tracked mesh carries it as the face moves. Quaternions are (w, x, y, z).
#pragma once

#include <torch/types.h>

namespace headforge {

struct TriangleFrames {
  torch::Tensor origin;    // [T, 3] centroid
  torch::Tensor rotation;  // [T, 3, 3] columns: edge, normal x edge, normal
  torch::Tensor quat;      // [T, 4] the rotation as a unit quaternion
  torch::Tensor scale;     // [T] mean edge length, at least 1e-6

  TriangleFrames To(torch::Device device) const {
    return {origin.to(device), rotation.to(device), quat.to(device), scale.to(device)};
  }
};

// vertices [V, 3], triangles [T, 3] (int64 vertex indices). A degenerate
// triangle (no area, a zero edge) gets the identity rotation and the floor
// scale, so Gaussians bound to it stay finite.
TriangleFrames ComputeTriangleFrames(const torch::Tensor& vertices, const torch::Tensor& triangles);
// The same frames for the triangles `wanted` ([K] int64, repeats allowed)
// only, at their rows of [T] tensors (every other row zero): all that
// ApplyBinding reads for Gaussians bound to them, for a fraction of the work
// where few of the mesh's triangles carry Gaussians. Each row equals the
// whole mesh's to the bit.
TriangleFrames ComputeTriangleFrames(const torch::Tensor& vertices, const torch::Tensor& triangles,
                                     const torch::Tensor& wanted);

struct BoundGaussians {
  torch::Tensor means;       // [N, 3]
  torch::Tensor quats;       // [N, 4]
  torch::Tensor log_scales;  // [N, 3]
};

// World Gaussians from local ones: mean = origin + scale * R local_mean,
// rotation = R * local rotation, scales = scale * local scales, for the
// triangle `binding` [N] (int64) of each. Differentiable in the local values
// (and the frames).
BoundGaussians ApplyBinding(const TriangleFrames& frames, const torch::Tensor& binding,
                            const torch::Tensor& local_means, const torch::Tensor& local_quats,
                            const torch::Tensor& local_log_scales);

// The local values that ApplyBinding maps to the given world ones.
BoundGaussians ToLocal(const TriangleFrames& frames, const torch::Tensor& binding, const torch::Tensor& means,
                       const torch::Tensor& quats, const torch::Tensor& log_scales);

// a * b for quaternions [..., 4].
torch::Tensor QuatMultiply(const torch::Tensor& a, const torch::Tensor& b);
// The unit quaternion of rotation matrices [..., 3, 3], w >= 0.
torch::Tensor RotationToQuat(const torch::Tensor& rotation);

}  // namespace headforge
