// `headforge face-model`: tools for the face model file. `import-ict` converts
// ICT-FaceKit's model folder into the Basel-layout HDF5 file the stages read.
#include <cstdio>

#include "core/log.h"
#include "pipelines/commands.h"
#include "reconstruction/face_model_import.h"

namespace headforge {
namespace {

constexpr const char* kFaceModelUsage =
    "Usage: headforge face-model <subcommand> [options]\n"
    "  import-ict DIR --out FILE.h5   convert ICT-FaceKit's FaceXModel folder into the face model file\n"
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

}  // namespace

int FaceModelCommand(const std::vector<std::string>& args) {
  if (!args.empty() && args[0] == "import-ict")
    return ImportIctCommand(std::vector<std::string>(args.begin() + 1, args.end()));
  const bool help = !args.empty() && (args[0] == "--help" || args[0] == "-h");
  if (!args.empty() && !help)
    std::fprintf(stderr, "headforge: face-model: unknown subcommand '%s'\n", args[0].c_str());
  std::fputs(kFaceModelUsage, help ? stdout : stderr);
  return help ? kExitOk : kExitUsage;
}

}  // namespace headforge
