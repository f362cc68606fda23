// Align's options: their checks and their command-line and config names.
#include "calibration/align.h"

namespace headforge {

Status AlignOptions::Check() const {
  if (!(inlier_mm > 0)) return Status::InvalidArgument("--inlier-mm must be positive");
  if (!(max_reprojection_px > 0)) return Status::InvalidArgument("--max-reprojection must be positive");
  if (!(max_yaw_deg > 0)) return Status::InvalidArgument("--max-yaw must be positive");
  if (!(max_elevation_deg > 0)) return Status::InvalidArgument("--max-elevation must be positive");
  if (select_views != "geometry" && select_views != "pnp")
    return Status::InvalidArgument("--align-select-views must be geometry or pnp");
  if (method != "views" && method != "landmarks") return Status::InvalidArgument("--align-method must be views or landmarks");
  if (refine != "reprojection" && refine != "off") return Status::InvalidArgument("--align-refine must be reprojection or off");
  if (!(refine_robust_px > 0)) return Status::InvalidArgument("--align-refine-robust must be positive");
  if (!(max_residual_mm > 0)) return Status::InvalidArgument("--max-align-residual must be positive");
  if (surface != "points" && surface != "off") return Status::InvalidArgument("--align-surface must be points or off");
  if (rig_view_poses != "mesh" && rig_view_poses != "landmarks")
    return Status::InvalidArgument("--align-rig-view-poses must be mesh or landmarks");
  if (!(surface_noise_mm > 0)) return Status::InvalidArgument("--align-surface-noise must be positive");
  if (surface_instants < 1) return Status::InvalidArgument("--align-surface-instants must be at least 1");
  return Status::Ok();
}

void AddAlignOptions(OptionSet* o, AlignOptions* a) {
  o->Add("align.inlier_mm", &a->inlier_mm, "RANSAC inlier threshold for landmark pairs, millimetres.", "inlier-mm");
  o->Add("align.max_reprojection_px", &a->max_reprojection_px,
         "Drop triangulated landmarks that reproject worse than this (px).", "max-reprojection");
  o->Add("align.landmark_embedding", &a->landmark_embedding,
         "Where the detector's 68 landmarks sit on the face model; empty: the model's landmark vertices.",
         "align-landmark-embedding", OptionSet::Effect::kRuntime);  // its contents count instead (the job's inputs)
  o->Add("align.method", &a->method,
         "views: rotation from the views' head poses, scale and translation from the landmarks; "
         "landmarks: Umeyama on triangulated landmarks.",
         "align-method");
  o->Add("align.max_yaw_deg", &a->max_yaw_deg,
         "Use landmarks only from views whose head yaw is within this many degrees of frontal.", "max-yaw");
  o->Add("align.max_elevation_deg", &a->max_elevation_deg,
         "With --align-select-views geometry: views more than this many degrees above or below the face give no "
         "head pose.",
         "max-elevation");
  o->Add("align.select_views", &a->select_views,
         "Which views' head poses give the rotation: geometry (the views whose cameras face the face within "
         "--max-yaw and --max-elevation under the rotation so far, repeated until the choice settles) or pnp (the "
         "views whose own PnP yaw is within --max-yaw).",
         "align-select-views");
  o->Add("align.refine", &a->refine,
         "reprojection: with the rotation held, refine scale and translation by reprojecting the model's landmarks "
         "into the views (no depth dilution from triangulation); off: the fit to triangulated landmarks.",
         "align-refine");
  o->Add("align.refine_robust_px", &a->refine_robust_px, "Huber scale of the reprojection refinement, pixels.",
         "align-refine-robust");
  o->Add("align.surface", &a->surface,
         "points: fit the face model's surface, with the subject's identity, to thousands of points triangulated "
         "on the face (one camera round a still head: from all its frames; several cameras, with --align-rig-surface: "
         "from each instant's "
         "views, the head at each instant's own pose), and take the head frame's rotation, translation and scale "
         "from it; off: keep the landmarks' head frame.",
         "align-surface");
  o->Add("align.rig_surface", &a->rig_surface,
         "Several cameras (a rig): run the surface fit too, over the instants (the head frame nearer the truth: "
         "dome_360 2.30 -> 0.52 deg, rig_8cam 1.77 -> 0.60 deg; but the dome's avatar trained on it scored 1.3 dB "
         "lower, so it is not the default).",
         "align-rig-surface");
  o->Add("align.surface_instants", &a->surface_instants,
         "Surface fit with several cameras: the instants it uses at most, the reference instant and others spread "
         "over the capture (on rig_8cam 50 instants took the head frame from 1.77 to 0.49 deg off, 16 to 0.55 deg; "
         "about 0.35 s an instant of 8 views).",
         "align-surface-instants");
  o->Add("align.surface_noise_mm", &a->surface_noise_mm,
         "Surface fit: the points' noise (mm), against which one standard deviation of an identity coefficient "
         "weighs.",
         "align-surface-noise");
  o->Add("align.rig_view_poses", &a->rig_view_poses,
         "Several cameras (a rig): mesh: each view's head pose from the face mesh's 468 points where ingest found "
         "them (the 68-point predictor reads a turned face as nearly frontal); landmarks: from the 68 points.",
         "align-rig-view-poses");
  o->Add("align.mesh_embedding", &a->mesh_embedding, "The face mesh's points on the face model (embed-mesh).",
         "align-mesh-embedding");
  o->Add("align.drop_misplaced", &a->drop_misplaced,
         "Leave out the views whose frames show the head but whose camera calibrate placed with the head behind it "
         "or well outside its frame (a wrong registration), and say which; more than half of them: fail.",
         "drop-misplaced");
  o->Add("align.max_residual_mm", &a->max_residual_mm,
         "Fail when the triangulated landmarks miss the face model by more than this median (mm): the cameras do not "
         "see one consistent head.",
         "max-align-residual");
}

}  // namespace headforge
