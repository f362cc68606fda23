// alignment.json: align's result written and read back (align.h).
#include "calibration/align.h"

#include <nlohmann/json.hpp>

#include "core/json_io.h"

namespace headforge {

Status WriteAlignment(const AlignResult& r, const fs::path& path) {
  nlohmann::json residuals = nlohmann::json::array();
  for (size_t k = 0; k < r.landmarks_used.size(); ++k)
    residuals.push_back({{"landmark", r.landmarks_used[k]}, {"residual_mm", r.residuals_mm[k]}, {"inlier", static_cast<bool>(r.inlier[k])}});
  nlohmann::json rotation = nlohmann::json::array(), matrix = nlohmann::json::array();
  for (int i = 0; i < 3; ++i)
    rotation.push_back({r.head_from_world.rotation(i, 0), r.head_from_world.rotation(i, 1), r.head_from_world.rotation(i, 2)});
  const Eigen::Matrix4d m = r.head_from_world.Matrix();
  for (int i = 0; i < 4; ++i) matrix.push_back({m(i, 0), m(i, 1), m(i, 2), m(i, 3)});
  const nlohmann::json j = {
      {"version", kAlignmentVersion},
      {"head_from_world", {{"scale", r.head_from_world.scale}, {"rotation", rotation},
                           {"translation", {r.head_from_world.translation.x(), r.head_from_world.translation.y(), r.head_from_world.translation.z()}},
                           {"matrix", matrix}}},
      {"quality", SimilarityQualityName(r.quality)},
      {"method", r.method},
      {"reference_frame", r.reference_frame},
      {"views_used", r.views_used},
      {"reprojection_median_px", r.reprojection_median_px},
      {"surface",
       {{"face_points", r.face_points}, {"points", r.surface_points}, {"median_mm", r.surface_median_mm},
        {"turn_deg", r.surface_turn_deg}, {"scale_change", r.surface_scale_change}, {"note", r.surface_note}}},
      {"rms_mm", r.rms_mm},
      {"median_mm", r.median_mm},
      {"residuals", residuals},
      {"cameras", "cameras_head.json"},
      {"message", r.message}};
  return WriteJsonAtomic(path, j, 1);
}

Status ReadAlignment(const fs::path& path, AlignResult* result) {
  nlohmann::json j;
  HF_RETURN_IF_ERROR(ReadArtefact(path, kAlignmentVersion, "align", &j));
  AlignResult r;
  try {
    const auto& h = j.at("head_from_world");
    r.head_from_world.scale = h.at("scale").get<double>();
    for (int i = 0; i < 3; ++i) {
      for (int k = 0; k < 3; ++k) r.head_from_world.rotation(i, k) = h.at("rotation").at(i).at(k).get<double>();
      r.head_from_world.translation[i] = h.at("translation").at(i).get<double>();
    }
    const std::string quality = j.at("quality").get<std::string>();
    bool known = false;
    for (SimilarityQuality q : {SimilarityQuality::kGood, SimilarityQuality::kPlanar, SimilarityQuality::kReflection,
                                SimilarityQuality::kDegenerate}) {
      if (quality == SimilarityQualityName(q)) {
        r.quality = q;
        known = true;
      }
    }
    if (!known) return Status::DataError(path.string() + ": unknown quality '" + quality + "'; run headforge align again");
    r.method = j.at("method").get<std::string>();
    r.reference_frame = j.at("reference_frame").get<int>();
    r.views_used = j.at("views_used").get<int>();
    r.reprojection_median_px = j.at("reprojection_median_px").get<double>();
    const auto& surface = j.at("surface");
    r.face_points = surface.at("face_points").get<int>();
    r.surface_points = surface.at("points").get<int>();
    r.surface_median_mm = surface.at("median_mm").get<double>();
    r.surface_turn_deg = surface.at("turn_deg").get<double>();
    r.surface_scale_change = surface.at("scale_change").get<double>();
    r.surface_note = surface.at("note").get<std::string>();
    r.rms_mm = j.at("rms_mm").get<double>();
    r.median_mm = j.at("median_mm").get<double>();
    for (const auto& residual : j.at("residuals")) {
      r.landmarks_used.push_back(residual.at("landmark").get<int>());
      r.residuals_mm.push_back(residual.at("residual_mm").get<double>());
      r.inlier.push_back(residual.at("inlier").get<bool>());
    }
    r.message = j.at("message").get<std::string>();
  } catch (const nlohmann::json::exception& e) {
    return Status::DataError(path.string() + " is damaged (" + e.what() + "); run headforge align again");
  }
  *result = std::move(r);
  return Status::Ok();
}

}  // namespace headforge
