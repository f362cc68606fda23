// `headforge face-model`: tools for the face model file. `import-ict` converts
// ICT-FaceKit's model folder into the Basel-layout HDF5 file the stages read;
// `inspect` summarises a model file and how far its identity modes can
// imitate a rigid motion of the head.
#include <cstdio>

#include "core/face_model.h"
#include "core/fs.h"
#include "core/log.h"
#include "pipelines/commands.h"
#include "reconstruction/face_model_import.h"
#include "reconstruction/pose_identity.h"

namespace headforge {
namespace {

constexpr const char* kFaceModelUsage =
    "Usage: headforge face-model <subcommand> [options]\n"
    "  import-ict DIR --out FILE.h5   convert ICT-FaceKit's FaceXModel folder into the face model file\n"
    "  inspect [--face-model FILE]    what a model file holds; how far its identity modes imitate head motion\n"
    "(headforge face-model <subcommand> --help lists its options)\n";

int ImportIctCommand(const std::vector<std::string>& args) {
  OptionSet options;
  CommonOptions common;
  AddCommonOptions(&options, &common, /*with_workspace=*/false);
  std::string dir, out;
  IctImportOptions import;
  options.AddPositional("DIR", &dir, "ICT-FaceKit's FaceXModel folder.");
  options.Add("face_model.out", &out, "Face model file to write (HDF5, Basel layout with the ICT extensions).",
              "out", OptionSet::Effect::kRuntime);
  options.Add("face_model.scale", &import.scale, "Metres per OBJ unit; ICT-FaceKit's OBJs are in centimetres.",
              "scale");
  options.Add("face_model.max_identities", &import.max_identities,
              "Keep only the first K identity shapes (identity000.obj ...); 0 keeps all.", "max-identities");
  const std::string usage = "headforge face-model import-ict DIR --out FILE.h5";
  const int parsed = ParseOrExit(
      &options, args, usage,
      "Converts the original ICT-FaceKit model folder (FaceXModel/: generic_neutral_mesh.obj,\n"
      "identity000.obj ..., one OBJ per expression blendshape, vertex_indices.json) into the\n"
      "Basel-layout HDF5 face model the stages read (see ../shared/data/README.md): the neutral\n"
      "mesh with its polygons split into triangles, identity modes with their variances,\n"
      "blendshapes with their names, UVs, iBUG-68 landmark vertices, vertex masks and, for the\n"
      "released topology, the named regions.");
  if (parsed >= 0) return parsed;
  if (Status s = common.Check(false); !s.ok()) return ReportFailure(s);
  if (dir.empty()) return ReportFailure(Status::InvalidArgument("give the ICT-FaceKit folder (DIR)"));
  if (out.empty()) return ReportFailure(Status::InvalidArgument("give the output file with --out"));
  if (Status s = import.Check(); !s.ok()) return ReportFailure(s);
  ApplyCommonOptions(common);

  IctImportSummary summary;
  if (Status s = ImportIctFaceKit(dir, out, import, &summary); !s.ok()) return ReportFailure(s);
  HF_LOG(Info) << "face-model: wrote " << out << ": " << summary.num_vertices << " vertices, "
               << summary.num_triangles << " triangles (" << summary.num_polygons << " polygons), "
               << summary.num_identities << " identity modes, " << summary.num_expressions << " expressions, "
               << summary.num_uvs << " UVs, " << summary.num_landmarks << " landmarks, " << summary.num_regions
               << " regions";
  return kExitOk;
}

int InspectCommand(const std::vector<std::string>& args) {
  OptionSet options;
  CommonOptions common;
  AddCommonOptions(&options, &common, /*with_workspace=*/false);
  int modes = 20;
  std::vector<std::string> point_sets = {"landmarks", "face"};
  options.Add("face_model.modes", &modes, "Identity modes that imitate the motions (the tracker fits 20).", "modes");
  options.Add("face_model.points", &point_sets,
              "Points the motions move: landmarks (the iBUG-68 vertices), all, or a region's name.", "points");
  const int parsed = ParseOrExit(
      &options, args, "headforge face-model inspect [--face-model FILE]",
      "Prints what a face model file holds (vertices, triangles, identity modes, expressions,\n"
      "landmarks, regions), then, for each rigid motion of the head (1 deg about its x, y, z\n"
      "axes, 1 mm along them, 1% scale), how much of it the first --modes identity modes can\n"
      "reproduce (least squares on the chosen points). A fit of identity and head pose together\n"
      "cannot tell a motion from the modes' imitation of it; what the modes leave over (mm of\n"
      "surface per degree) is what the data must resolve for the head pose to be that accurate.");
  if (parsed >= 0) return parsed;
  if (Status s = common.Check(false); !s.ok()) return ReportFailure(s);
  ApplyCommonOptions(common);
  const std::string face_model = common.Settings().face_model;
  const bool defaults = point_sets == std::vector<std::string>{"landmarks", "face"};
  if (modes < 1) return ReportFailure(Status::InvalidArgument("--modes must be at least 1"));
  FaceModel model;
  if (Status s = FaceModel::Load(face_model, &model); !s.ok()) return ReportFailure(s);
  std::printf("%s\n  %d vertices, %d triangles, %d identity modes, %d expressions, %zu landmark vertices, %zu regions, %s\n",
              face_model.c_str(), model.num_vertices(), model.num_triangles(), model.num_identity(),
              model.num_expressions(), model.landmarks_ibug68().size(), model.regions().size(),
              model.has_uv() ? "UVs" : "no UVs");
  if (modes > model.num_identity()) {
    std::printf("  (the model has %d identity modes; using them all)\n", model.num_identity());
    modes = model.num_identity();
  }
  for (const std::string& points : point_sets) {
    // The default sets are skipped where a model lacks them; a set asked for is required.
    const bool missing = (points == "landmarks" && model.landmarks_ibug68().empty()) ||
                         (points != "landmarks" && points != "all" && model.FindRegion(points) == nullptr);
    if (missing && defaults) {
      std::printf("\n(no %s points in this model)\n", points.c_str());
      continue;
    }
    std::vector<RigidImitation> rows;
    if (Status s = ImitateRigidMotions(model, modes, points, &rows); !s.ok()) return ReportFailure(s);
    std::printf("\nRigid motions imitated by %d identity modes (points: %s; rotations and scale with a free "
                "translation):\n",
                modes, points.c_str());
    std::printf("  %-10s %-6s %10s %10s %12s %14s\n", "motion", "unit", "moves (mm)", "shared (%)", "|alpha|",
                "left over (mm)");
    for (const RigidImitation& r : rows)
      std::printf("  %-10s %-6s %10.3f %10.1f %12.2f %14.3f\n", r.motion.c_str(), r.unit.c_str(), r.motion_mm,
                  100 * r.shared, r.alpha_norm, r.left_over_mm);
  }
  return kExitOk;
}

}  // namespace

int FaceModelCommand(const std::vector<std::string>& args) {
  if (!args.empty() && args[0] == "import-ict")
    return ImportIctCommand(std::vector<std::string>(args.begin() + 1, args.end()));
  if (!args.empty() && args[0] == "inspect")
    return InspectCommand(std::vector<std::string>(args.begin() + 1, args.end()));
  const bool help = !args.empty() && (args[0] == "--help" || args[0] == "-h");
  if (!args.empty() && !help)
    std::fprintf(stderr, "headforge: face-model: unknown subcommand '%s'\n", args[0].c_str());
  std::fputs(kFaceModelUsage, help ? stdout : stderr);
  return help ? kExitOk : kExitUsage;
}

}  // namespace headforge
