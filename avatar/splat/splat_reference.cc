#include "avatar/splat/splat_reference.h"

#include <torch/torch.h>

#include <cmath>

#include "avatar/splat/splat_kernels.h"

namespace headforge::splat_reference {

using torch::Tensor;

ProjectResult Project(const Tensor& means, const Tensor& quats, const Tensor& log_scales,
                      const SplatCamera& camera, const SplatOptions& options) {
  const auto p = splat::ProjectParams::From(camera, options);
  const auto opts = means.options();
  const Tensor w = torch::tensor(std::vector<double>(p.rotation, p.rotation + 9), torch::kFloat64).to(opts).view({3, 3});
  const Tensor t = torch::tensor(std::vector<double>(p.translation, p.translation + 3), torch::kFloat64).to(opts);
  const Tensor cam = torch::matmul(means, w.t()) + t;
  const Tensor z = cam.select(1, 2);
  const Tensor in_depth = (z >= p.near_plane) & (z <= p.far_plane);
  const Tensor zs = torch::where(in_depth, z, torch::ones_like(z));

  const Tensor q = quats / quats.norm(2, 1, true);
  const Tensor qw = q.select(1, 0), qx = q.select(1, 1), qy = q.select(1, 2), qz = q.select(1, 3);
  const Tensor rot = torch::stack({1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy - qw * qz),
                                   2 * (qx * qz + qw * qy), 2 * (qx * qy + qw * qz),
                                   1 - 2 * (qx * qx + qz * qz), 2 * (qy * qz - qw * qx),
                                   2 * (qx * qz - qw * qy), 2 * (qy * qz + qw * qx),
                                   1 - 2 * (qx * qx + qy * qy)},
                                  1)
                         .view({-1, 3, 3});
  const Tensor m = rot * log_scales.exp().unsqueeze(1);
  const Tensor sigma = torch::matmul(m, m.transpose(1, 2));
  const Tensor cov_cam = torch::matmul(torch::matmul(w, sigma), w.t());

  const Tensor rx = cam.select(1, 0) / zs, ry = cam.select(1, 1) / zs;
  const Tensor tx = zs * rx.clamp(-p.lim_x_neg, p.lim_x_pos);
  const Tensor ty = zs * ry.clamp(-p.lim_y_neg, p.lim_y_pos);
  const Tensor zero = torch::zeros_like(zs);
  const Tensor jac = torch::stack({p.fx / zs, zero, -p.fx * tx / (zs * zs), zero, p.fy / zs,
                                   -p.fy * ty / (zs * zs)},
                                  1)
                         .view({-1, 2, 3});
  const Tensor cov2d = torch::matmul(torch::matmul(jac, cov_cam), jac.transpose(1, 2));
  const Tensor ca = cov2d.select(1, 0).select(1, 0) + p.eps2d;
  const Tensor cb = cov2d.select(1, 0).select(1, 1);
  const Tensor cc = cov2d.select(1, 1).select(1, 1) + p.eps2d;
  const Tensor det = ca * cc - cb * cb;
  const Tensor u = p.fx * rx + p.cx, v = p.fy * ry + p.cy;

  Tensor radii, visible;
  {
    torch::NoGradGuard no_grad;
    const Tensor mid = 0.5 * (ca + cc);
    const Tensor lambda = mid + (mid * mid - det).clamp_min(0.1).sqrt();
    const Tensor radius = (3.0 * lambda.sqrt()).ceil();
    visible = in_depth & (det > 0) & torch::isfinite(det) & torch::isfinite(radius) &
              (u + radius >= 0) & (u - radius <= p.width - 1) & (v + radius >= 0) &
              (v - radius <= p.height - 1);
    radii = torch::where(visible, radius.clamp_max(1e8), torch::zeros_like(radius)).to(torch::kInt32);
  }
  const Tensor dets = torch::where(visible, det, torch::ones_like(det));
  const Tensor conics = torch::stack({cc / dets, -cb / dets, ca / dets}, 1);
  const Tensor keep = visible.unsqueeze(1);
  ProjectResult out;
  out.means2d = torch::where(keep, torch::stack({u, v}, 1), torch::zeros({1}, opts));
  out.conics = torch::where(keep, conics, torch::zeros({1}, opts));
  out.depths = torch::where(visible, z, torch::zeros({1}, opts));
  out.radii = radii;
  return out;
}

RasterizeResult Rasterize(const Tensor& means2d, const Tensor& conics, const Tensor& features,
                          const Tensor& opacities, const Tensor& background, const Tensor& radii,
                          const Tensor& depths, int width, int height) {
  const auto opts = means2d.options();
  const int64_t channels = features.size(1);
  const Tensor order = std::get<1>(torch::sort(depths.detach(), /*stable=*/true, 0, false));
  const Tensor m = means2d.index_select(0, order);
  const Tensor con = conics.index_select(0, order);
  const Tensor f = features.index_select(0, order);
  const Tensor o = opacities.index_select(0, order);
  const Tensor r = radii.index_select(0, order).to(opts.dtype());

  const Tensor ys = torch::arange(height, opts).view({height, 1}).expand({height, width}).reshape({-1, 1});
  const Tensor xs = torch::arange(width, opts).view({1, width}).expand({height, width}).reshape({-1, 1});
  const Tensor dx = m.select(1, 0).unsqueeze(0) - xs;  // [P, N]
  const Tensor dy = m.select(1, 1).unsqueeze(0) - ys;
  const Tensor a = con.select(1, 0).unsqueeze(0), b = con.select(1, 1).unsqueeze(0),
               c = con.select(1, 2).unsqueeze(0);
  const Tensor sigma = 0.5 * (a * dx * dx + c * dy * dy) + b * dx * dy;
  const Tensor alpha = (o.unsqueeze(0) * torch::exp(-sigma)).clamp_max(0.999);

  Tensor contrib;
  {
    torch::NoGradGuard no_grad;
    const double s = kSplatTileSize;
    const Tensor mx = m.select(1, 0).detach(), my = m.select(1, 1).detach();
    const Tensor tx0 = ((mx - r) / s).floor(), tx1 = ((mx + r) / s).floor();
    const Tensor ty0 = ((my - r) / s).floor(), ty1 = ((my + r) / s).floor();
    const Tensor ptx = (xs / s).floor(), pty = (ys / s).floor();
    const Tensor on_tile = (r > 0).unsqueeze(0) & (ptx >= tx0.unsqueeze(0)) &
                           (ptx <= tx1.unsqueeze(0)) & (pty >= ty0.unsqueeze(0)) &
                           (pty <= ty1.unsqueeze(0));
    const Tensor valid = on_tile & (sigma >= 0) & (alpha >= 1.0 / 255.0);
    const Tensor through = torch::cumprod(1 - torch::where(valid, alpha, torch::zeros_like(alpha)), 1);
    contrib = valid & (through >= 1e-4);
  }
  const Tensor alpha_c = torch::where(contrib, alpha, torch::zeros_like(alpha));
  const Tensor through = torch::cumprod(1 - alpha_c, 1);
  const Tensor before = torch::cat({torch::ones({through.size(0), 1}, opts),
                                    through.slice(1, 0, through.size(1) - 1)},
                                   1);
  const Tensor weight = alpha_c * before;
  const Tensor t_final = through.size(1) > 0 ? through.select(1, through.size(1) - 1)
                                             : torch::ones({int64_t(width) * height}, opts);
  const Tensor bg = background.defined() ? background : torch::zeros({channels}, opts);
  const Tensor image = torch::matmul(weight, f) + t_final.unsqueeze(1) * bg.unsqueeze(0);
  RasterizeResult out;
  out.image = image.t().reshape({channels, height, width});
  out.alpha = (1 - t_final).reshape({height, width});
  return out;
}

}  // namespace headforge::splat_reference
