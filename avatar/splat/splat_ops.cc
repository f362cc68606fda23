// Input checks, output allocation, device dispatch and the autograd
// Functions of the splatting stages. Kernels live in splat_*_cpu.cc.
#include "avatar/splat/splat_ops.h"

#include <torch/torch.h>

#include "avatar/splat/splat_kernels.h"

namespace headforge {
namespace splat {

ProjectParams ProjectParams::From(const SplatCamera& camera, const SplatOptions& options) {
  ProjectParams p{};
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) p.rotation[3 * i + j] = camera.cam_from_world[4 * i + j];
    p.translation[i] = camera.cam_from_world[4 * i + 3];
  }
  p.fx = camera.fx;
  p.fy = camera.fy;
  p.cx = camera.cx;
  p.cy = camera.cy;
  p.width = camera.width;
  p.height = camera.height;
  p.near_plane = options.near_plane;
  p.far_plane = options.far_plane;
  p.eps2d = options.eps2d;
  const double margin_x = options.clip_margin * camera.width / camera.fx;
  const double margin_y = options.clip_margin * camera.height / camera.fy;
  p.lim_x_neg = (camera.cx + 0.5) / camera.fx + margin_x;
  p.lim_x_pos = (camera.width - 0.5 - camera.cx) / camera.fx + margin_x;
  p.lim_y_neg = (camera.cy + 0.5) / camera.fy + margin_y;
  p.lim_y_pos = (camera.height - 0.5 - camera.cy) / camera.fy + margin_y;
  return p;
}

namespace {

using torch::Tensor;
using torch::autograd::AutogradContext;
using torch::autograd::variable_list;

// ProjectParams through the autograd context (which stores IValues).
std::vector<double> Pack(const ProjectParams& p) {
  std::vector<double> v(p.rotation, p.rotation + 9);
  v.insert(v.end(), p.translation, p.translation + 3);
  v.insert(v.end(), {p.fx, p.fy, p.cx, p.cy, double(p.width), double(p.height), p.near_plane,
                     p.far_plane, p.eps2d, p.lim_x_neg, p.lim_x_pos, p.lim_y_neg, p.lim_y_pos});
  return v;
}

ProjectParams Unpack(const std::vector<double>& v) {
  ProjectParams p{};
  std::copy(v.begin(), v.begin() + 9, p.rotation);
  std::copy(v.begin() + 9, v.begin() + 12, p.translation);
  p.fx = v[12];
  p.fy = v[13];
  p.cx = v[14];
  p.cy = v[15];
  p.width = static_cast<int>(v[16]);
  p.height = static_cast<int>(v[17]);
  p.near_plane = v[18];
  p.far_plane = v[19];
  p.eps2d = v[20];
  p.lim_x_neg = v[21];
  p.lim_x_pos = v[22];
  p.lim_y_neg = v[23];
  p.lim_y_pos = v[24];
  return p;
}

// The kernel set for a tensor's device: CPU always, CUDA in builds whose
// LibTorch has it (HEADFORGE_WITH_CUDA); other devices get a clear error.
struct Backend {
  decltype(&cpu::ProjectForward) project_forward;
  decltype(&cpu::ProjectBackward) project_backward;
  decltype(&cpu::IntersectTiles) intersect_tiles;
  decltype(&cpu::RasterizeForward) rasterize_forward;
  decltype(&cpu::RasterizeBackward) rasterize_backward;
};

const Backend& BackendFor(const Tensor& t, const char* op) {
  static const Backend kCpu{cpu::ProjectForward, cpu::ProjectBackward, cpu::IntersectTiles,
                            cpu::RasterizeForward, cpu::RasterizeBackward};
  if (t.device().is_cpu()) return kCpu;
#ifdef HEADFORGE_WITH_CUDA
  static const Backend kCuda{cuda::ProjectForward, cuda::ProjectBackward, cuda::IntersectTiles,
                             cuda::RasterizeForward, cuda::RasterizeBackward};
  if (t.device().is_cuda()) return kCuda;
  TORCH_CHECK(false, op, ": no kernels for device ", t.device(), " (this build has CPU and CUDA)");
#else
  TORCH_CHECK(false, op, ": no kernels for device ", t.device(),
              " in this build (built for CPU: LibTorch without CUDA was found)");
#endif
}

void CheckFloat(const Tensor& t, const Tensor& like, const char* op, const char* name) {
  TORCH_CHECK(t.scalar_type() == like.scalar_type(), op, ": ", name, " has type ", t.scalar_type(),
              ", expected ", like.scalar_type());
  TORCH_CHECK(t.device() == like.device(), op, ": ", name, " is on ", t.device(), ", expected ",
              like.device());
}

class ProjectFunction : public torch::autograd::Function<ProjectFunction> {
 public:
  static variable_list forward(AutogradContext* ctx, const Tensor& means, const Tensor& quats,
                               const Tensor& log_scales, const ProjectParams& params) {
    const int64_t n = means.size(0);
    auto means2d = torch::empty({n, 2}, means.options());
    auto conics = torch::empty({n, 3}, means.options());
    auto depths = torch::empty({n}, means.options());
    auto radii = torch::empty({n}, means.options().dtype(torch::kInt32));
    BackendFor(means, "ProjectGaussians")
        .project_forward(means, quats, log_scales, params, means2d, conics, depths, radii);
    ctx->save_for_backward({means, quats, log_scales, radii});
    ctx->saved_data["params"] = Pack(params);
    ctx->mark_non_differentiable({radii});
    return {means2d, conics, depths, radii};
  }

  static variable_list backward(AutogradContext* ctx, variable_list grads) {
    const auto saved = ctx->get_saved_variables();
    const Tensor& means = saved[0];
    const ProjectParams params = Unpack(ctx->saved_data["params"].toDoubleVector());
    auto grad_or_zeros = [&](const Tensor& g, std::initializer_list<int64_t> shape) {
      return g.defined() ? g.contiguous() : torch::zeros(shape, means.options());
    };
    const int64_t n = means.size(0);
    const Tensor v_means2d = grad_or_zeros(grads[0], {n, 2});
    const Tensor v_conics = grad_or_zeros(grads[1], {n, 3});
    const Tensor v_depths = grad_or_zeros(grads[2], {n});
    auto v_means = torch::empty_like(means);
    auto v_quats = torch::empty_like(saved[1]);
    auto v_log_scales = torch::empty_like(saved[2]);
    BackendFor(means, "ProjectGaussians")
        .project_backward(means, saved[1], saved[2], saved[3], params, v_means2d, v_conics,
                          v_depths, v_means, v_quats, v_log_scales);
    return {v_means, v_quats, v_log_scales, Tensor()};
  }
};

class RasterizeFunction : public torch::autograd::Function<RasterizeFunction> {
 public:
  static variable_list forward(AutogradContext* ctx, const Tensor& means2d, const Tensor& conics,
                               const Tensor& features, const Tensor& opacities,
                               const Tensor& background, const Tensor& tile_offsets,
                               const Tensor& gaussian_ids, int64_t width, int64_t height) {
    const int64_t channels = features.size(1);
    auto image = torch::empty({channels, height, width}, features.options());
    auto transmittance = torch::empty({height, width}, features.options());
    auto last = torch::empty({height, width}, features.options().dtype(torch::kInt32));
    BackendFor(means2d, "RasterizeGaussians")
        .rasterize_forward(means2d, conics, features, opacities, background, tile_offsets,
                           gaussian_ids, int(width), int(height), image, transmittance, last);
    ctx->save_for_backward({means2d, conics, features, opacities, background, tile_offsets,
                            gaussian_ids, transmittance, last});
    ctx->saved_data["width"] = width;
    ctx->saved_data["height"] = height;
    return {image, 1 - transmittance};
  }

  static variable_list backward(AutogradContext* ctx, variable_list grads) {
    const auto s = ctx->get_saved_variables();
    const int width = static_cast<int>(ctx->saved_data["width"].toInt());
    const int height = static_cast<int>(ctx->saved_data["height"].toInt());
    const Tensor& transmittance = s[7];
    const Tensor v_image = grads[0].defined()
                               ? grads[0].contiguous()
                               : torch::zeros({s[2].size(1), height, width}, s[2].options());
    const Tensor v_alpha =
        grads[1].defined() ? grads[1].contiguous() : torch::zeros_like(transmittance);
    // [N, kGradFeatures + C], columns as GradientColumn.
    const Tensor total = BackendFor(s[0], "RasterizeGaussians")
                             .rasterize_backward(s[0], s[1], s[2], s[3], s[4], s[5], s[6], width,
                                                 height, transmittance, s[8], v_image, v_alpha);
    const Tensor v_means2d = total.slice(1, kGradMx, kGradMy + 1).contiguous();
    const Tensor v_conics = total.slice(1, kGradA, kGradC + 1).contiguous();
    const Tensor v_opacities = total.select(1, kGradO).contiguous();
    const Tensor v_features = total.slice(1, kGradFeatures).contiguous();
    const Tensor v_background = (v_image * transmittance.unsqueeze(0)).sum({1, 2});
    return {v_means2d, v_conics, v_features, v_opacities, v_background,
            Tensor(),  Tensor(), Tensor(),   Tensor()};
  }
};

}  // namespace
}  // namespace splat

ProjectResult ProjectGaussians(const torch::Tensor& means, const torch::Tensor& quats,
                               const torch::Tensor& log_scales, const SplatCamera& camera,
                               const SplatOptions& options) {
  const char* op = "ProjectGaussians";
  std::string why;
  TORCH_CHECK(options.Check(&why), op, ": ", why);
  TORCH_CHECK(camera.width > 0 && camera.height > 0 && camera.fx > 0 && camera.fy > 0, op,
              ": the camera needs a positive size and focal length");
  TORCH_CHECK(means.dim() == 2 && means.size(1) == 3, op, ": means must be [N, 3], got ",
              means.sizes());
  TORCH_CHECK(means.is_floating_point(), op, ": means must be float or double");
  const int64_t n = means.size(0);
  TORCH_CHECK(quats.dim() == 2 && quats.size(0) == n && quats.size(1) == 4, op,
              ": quats must be [N, 4], got ", quats.sizes());
  TORCH_CHECK(log_scales.dim() == 2 && log_scales.size(0) == n && log_scales.size(1) == 3, op,
              ": log_scales must be [N, 3], got ", log_scales.sizes());
  splat::CheckFloat(quats, means, op, "quats");
  splat::CheckFloat(log_scales, means, op, "log_scales");
  splat::BackendFor(means, op);
  const auto out =
      splat::ProjectFunction::apply(means.contiguous(), quats.contiguous(), log_scales.contiguous(),
                                    splat::ProjectParams::From(camera, options));
  return {out[0], out[1], out[2], out[3]};
}

TileIntersections IntersectTiles(const torch::Tensor& means2d, const torch::Tensor& radii,
                                 const torch::Tensor& depths, int width, int height) {
  const char* op = "IntersectTiles";
  TORCH_CHECK(width > 0 && height > 0, op, ": the image needs a positive size");
  TORCH_CHECK(means2d.dim() == 2 && means2d.size(1) == 2, op, ": means2d must be [N, 2]");
  const int64_t n = means2d.size(0);
  TORCH_CHECK(radii.dim() == 1 && radii.size(0) == n && radii.scalar_type() == torch::kInt32, op,
              ": radii must be [N] int32");
  TORCH_CHECK(depths.dim() == 1 && depths.size(0) == n, op, ": depths must be [N]");
  splat::CheckFloat(depths, means2d, op, "depths");
  splat::BackendFor(means2d, op);
  TORCH_CHECK(radii.device() == means2d.device(), op, ": radii is on ", radii.device(),
              ", expected ", means2d.device());
  TileIntersections out;
  out.tiles_x = (width + kSplatTileSize - 1) / kSplatTileSize;
  out.tiles_y = (height + kSplatTileSize - 1) / kSplatTileSize;
  torch::NoGradGuard no_grad;
  std::tie(out.tile_offsets, out.gaussian_ids) =
      splat::BackendFor(means2d, op)
          .intersect_tiles(means2d.detach().contiguous(), radii.contiguous(),
                           depths.detach().contiguous(), out.tiles_x, out.tiles_y);
  return out;
}

RasterizeResult RasterizeGaussians(const torch::Tensor& means2d, const torch::Tensor& conics,
                                   const torch::Tensor& features, const torch::Tensor& opacities,
                                   const torch::Tensor& background, const TileIntersections& tiles,
                                   int width, int height) {
  const char* op = "RasterizeGaussians";
  TORCH_CHECK(width > 0 && height > 0, op, ": the image needs a positive size");
  TORCH_CHECK(means2d.dim() == 2 && means2d.size(1) == 2, op, ": means2d must be [N, 2]");
  TORCH_CHECK(means2d.is_floating_point(), op, ": means2d must be float or double");
  const int64_t n = means2d.size(0);
  TORCH_CHECK(conics.dim() == 2 && conics.size(0) == n && conics.size(1) == 3, op,
              ": conics must be [N, 3]");
  TORCH_CHECK(features.dim() == 2 && features.size(0) == n && features.size(1) >= 1, op,
              ": features must be [N, C] with C >= 1, got ", features.sizes());
  TORCH_CHECK(opacities.dim() == 1 && opacities.size(0) == n, op, ": opacities must be [N]");
  const int64_t channels = features.size(1);
  const int tiles_x = (width + kSplatTileSize - 1) / kSplatTileSize;
  const int tiles_y = (height + kSplatTileSize - 1) / kSplatTileSize;
  TORCH_CHECK(tiles.tiles_x == tiles_x && tiles.tiles_y == tiles_y &&
                  tiles.tile_offsets.numel() == int64_t(tiles_x) * tiles_y + 1,
              op, ": the tile lists were made for another image size");
  splat::CheckFloat(conics, means2d, op, "conics");
  splat::CheckFloat(features, means2d, op, "features");
  splat::CheckFloat(opacities, means2d, op, "opacities");
  splat::BackendFor(means2d, op);
  TORCH_CHECK(tiles.tile_offsets.device() == means2d.device() &&
                  tiles.gaussian_ids.device() == means2d.device(),
              op, ": the tile lists are on ", tiles.tile_offsets.device(), ", expected ",
              means2d.device());
  torch::Tensor bg = background;
  if (!bg.defined()) {
    bg = torch::zeros({channels}, features.options());
  } else {
    TORCH_CHECK(bg.dim() == 1 && bg.size(0) == channels, op, ": background must be [C] = [",
                channels, "], got ", bg.sizes());
    splat::CheckFloat(bg, means2d, op, "background");
  }
  const auto out = splat::RasterizeFunction::apply(
      means2d.contiguous(), conics.contiguous(), features.contiguous(), opacities.contiguous(),
      bg.contiguous(), tiles.tile_offsets, tiles.gaussian_ids, int64_t(width), int64_t(height));
  return {out[0], out[1]};
}

SplatRenderResult RenderGaussians(const torch::Tensor& means, const torch::Tensor& quats,
                                  const torch::Tensor& log_scales, const torch::Tensor& opacities,
                                  const torch::Tensor& features, const torch::Tensor& background,
                                  const SplatCamera& camera, const SplatRenderOptions& options) {
  const ProjectResult projected = ProjectGaussians(means, quats, log_scales, camera, options.splat);
  const TileIntersections tiles = IntersectTiles(projected.means2d, projected.radii,
                                                 projected.depths, camera.width, camera.height);
  torch::Tensor feats = features;
  torch::Tensor bg = background;
  if (options.depth) {
    feats = torch::cat({features, projected.depths.unsqueeze(1)}, 1);
    if (!bg.defined()) bg = torch::zeros({features.size(1)}, features.options());
    bg = torch::cat({bg, torch::zeros({1}, bg.options())});
  }
  const RasterizeResult raster =
      RasterizeGaussians(projected.means2d, projected.conics, feats, opacities, bg, tiles,
                         camera.width, camera.height);
  SplatRenderResult out;
  out.alpha = raster.alpha;
  out.means2d = projected.means2d;
  out.radii = projected.radii;
  if (options.depth) {
    const int64_t c = features.size(1);
    out.image = raster.image.slice(0, 0, c);
    const torch::Tensor covered = raster.alpha > 0;
    out.depth = torch::where(covered, raster.image[c] / raster.alpha.clamp_min(1e-10),
                             torch::zeros_like(raster.alpha));
  } else {
    out.image = raster.image;
  }
  return out;
}

}  // namespace headforge
