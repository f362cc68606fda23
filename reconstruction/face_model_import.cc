#include "reconstruction/face_model_import.h"

#include <H5Cpp.h>

#include <Eigen/Core>
#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <map>
#include <nlohmann/json.hpp>
#include <set>
#include <vector>

#include "core/fs.h"
#include "core/json_io.h"
#include "core/log.h"

namespace headforge {
namespace {

constexpr const char* kNeutralFile = "generic_neutral_mesh.obj";
constexpr const char* kIndicesFile = "vertex_indices.json";

// A polygon mesh as written in an OBJ file, in the file's units.
struct ObjMesh {
  std::vector<double> positions;     // x y z per vertex
  std::vector<float> uvs;            // u v per texture coordinate
  std::vector<int> corners;          // vertex index of each polygon corner
  std::vector<int> uv_corners;       // texture index of each corner, -1 if none
  std::vector<int> polygon_starts{0};  // first corner of each polygon, then the end

  int num_vertices() const { return static_cast<int>(positions.size() / 3); }
  int num_polygons() const { return static_cast<int>(polygon_starts.size()) - 1; }
};

bool IsBlank(char c) { return c == ' ' || c == '\t' || c == '\r'; }

template <typename T>
bool NextNumber(const char** p, const char* end, T* value) {
  while (*p < end && IsBlank(**p)) ++*p;
  if (*p < end && **p == '+') ++*p;  // from_chars does not take a leading '+'
  const auto result = std::from_chars(*p, end, *value);
  if (result.ec != std::errc()) return false;
  *p = result.ptr;
  return true;
}

// OBJ indices are 1-based, or negative counting back from the latest element.
bool ResolveIndex(long index, int count, int* resolved) {
  if (index > 0) *resolved = static_cast<int>(index - 1);
  else if (index < 0) *resolved = static_cast<int>(count + index);
  else return false;
  return true;
}

// Reads "v" lines, and with `with_faces` also "vt" and "f" lines; other
// statements (normals, groups, materials) do not matter here.
Status ReadObj(const fs::path& path, bool with_faces, ObjMesh* mesh) {
  std::string text;
  HF_RETURN_IF_ERROR(ReadFileToString(path, &text));
  ObjMesh m;
  int line_number = 0;
  auto error = [&](const std::string& what) {
    return Status::DataError(path.string() + ":" + std::to_string(line_number) + ": " + what);
  };
  size_t line_start = 0;
  while (line_start < text.size()) {
    size_t line_end = text.find('\n', line_start);
    if (line_end == std::string::npos) line_end = text.size();
    ++line_number;
    const char* p = text.data() + line_start;
    const char* end = text.data() + line_end;
    line_start = line_end + 1;
    while (p < end && IsBlank(*p)) ++p;
    if (end - p >= 2 && p[0] == 'v' && IsBlank(p[1])) {
      p += 2;
      double xyz[3];
      for (double& x : xyz)
        if (!NextNumber(&p, end, &x) || !std::isfinite(x)) return error("a vertex needs three finite coordinates");
      m.positions.insert(m.positions.end(), xyz, xyz + 3);
    } else if (!with_faces) {
      continue;
    } else if (end - p >= 3 && p[0] == 'v' && p[1] == 't' && IsBlank(p[2])) {
      p += 3;
      float uv[2];
      for (float& x : uv)
        if (!NextNumber(&p, end, &x) || !std::isfinite(x)) return error("a texture coordinate needs u and v");
      m.uvs.insert(m.uvs.end(), uv, uv + 2);
    } else if (end - p >= 2 && p[0] == 'f' && IsBlank(p[1])) {
      p += 2;
      const int num_uvs = static_cast<int>(m.uvs.size() / 2);
      int count = 0;
      while (true) {
        while (p < end && IsBlank(*p)) ++p;
        if (p == end) break;
        long v = 0, vt = 0;
        int vertex = -1, texture = -1;
        if (!NextNumber(&p, end, &v) || !ResolveIndex(v, m.num_vertices(), &vertex))
          return error("bad face corner (expected v, v/vt, v//vn or v/vt/vn)");
        if (p < end && *p == '/') {
          ++p;
          if (p < end && *p != '/') {
            if (!NextNumber(&p, end, &vt) || !ResolveIndex(vt, num_uvs, &texture))
              return error("bad texture index in a face corner");
          }
          if (p < end && *p == '/') {
            ++p;
            long vn = 0;
            if (!NextNumber(&p, end, &vn)) return error("bad normal index in a face corner");
          }
        }
        if (p < end && !IsBlank(*p)) return error("bad face corner (expected v, v/vt, v//vn or v/vt/vn)");
        m.corners.push_back(vertex);
        m.uv_corners.push_back(texture);
        ++count;
      }
      if (count < 3) return error("a face needs at least three corners");
      m.polygon_starts.push_back(static_cast<int>(m.corners.size()));
    }
  }
  if (m.num_vertices() == 0) return Status::DataError(path.string() + " has no vertices");
  for (int v : m.corners)
    if (v < 0 || v >= m.num_vertices())
      return Status::DataError(path.string() + ": a face names vertex " + std::to_string(v + 1) + " of " +
                               std::to_string(m.num_vertices()));
  for (int t : m.uv_corners)
    if (t >= static_cast<int>(m.uvs.size() / 2))
      return Status::DataError(path.string() + ": a face names a texture coordinate that does not exist");
  *mesh = std::move(m);
  return Status::Ok();
}

// Polygons split as fans from their first corner.
struct Triangulation {
  Eigen::Matrix3Xi triangles, uv_triangles;  // [3, T]; uv_triangles empty without UVs
  std::vector<int> first_triangle;           // per polygon, then the total
};

Status Triangulate(const ObjMesh& mesh, const std::string& name, Triangulation* out) {
  const bool any_uv = std::any_of(mesh.uv_corners.begin(), mesh.uv_corners.end(), [](int t) { return t >= 0; });
  const bool all_uv = std::all_of(mesh.uv_corners.begin(), mesh.uv_corners.end(), [](int t) { return t >= 0; });
  if (any_uv && !all_uv)
    return Status::DataError(name + ": some face corners have texture coordinates and others do not");
  int total = 0;
  out->first_triangle.clear();
  for (int p = 0; p < mesh.num_polygons(); ++p) {
    out->first_triangle.push_back(total);
    total += mesh.polygon_starts[p + 1] - mesh.polygon_starts[p] - 2;
  }
  out->first_triangle.push_back(total);
  out->triangles.resize(3, total);
  out->uv_triangles.resize(3, all_uv && total > 0 ? total : 0);
  int t = 0;
  for (int p = 0; p < mesh.num_polygons(); ++p) {
    const int first = mesh.polygon_starts[p];
    for (int c = first + 1; c + 1 < mesh.polygon_starts[p + 1]; ++c, ++t) {
      out->triangles.col(t) << mesh.corners[first], mesh.corners[c], mesh.corners[c + 1];
      if (out->uv_triangles.cols() > 0)
        out->uv_triangles.col(t) << mesh.uv_corners[first], mesh.uv_corners[c], mesh.uv_corners[c + 1];
    }
  }
  return Status::Ok();
}

struct IctIndices {
  std::vector<std::string> expressions;
  bool has_expressions = false;
  std::vector<int> landmarks, rigid_landmarks, rigid_vertices, fitting_vertices;
};

Status ReadIndexList(const nlohmann::json& json, const char* key, const std::string& file, std::vector<int>* out) {
  if (!json.contains(key)) return Status::Ok();
  const auto& list = json[key];
  const Status bad = Status::DataError(file + ": \"" + key + "\" must be a list of non-negative integers");
  if (!list.is_array()) return bad;
  for (const auto& item : list) {
    if (!item.is_number_integer()) return bad;
    const int64_t value = item.get<int64_t>();
    if (value < 0 || value > INT32_MAX) return bad;
    out->push_back(static_cast<int>(value));
  }
  return Status::Ok();
}

Status ReadIctIndices(const fs::path& path, IctIndices* indices) {
  nlohmann::json json;
  HF_RETURN_IF_ERROR(ReadJson(path, &json));
  const std::string file = path.string();
  if (!json.is_object()) return Status::DataError(file + " must hold a JSON object");
  if (json.contains("expressions")) {
    const auto& names = json["expressions"];
    const Status bad = Status::DataError(file + ": \"expressions\" must be a list of file names without .obj");
    if (!names.is_array()) return bad;
    std::set<std::string> seen;
    for (const auto& item : names) {
      if (!item.is_string()) return bad;
      const std::string name = item.get<std::string>();
      if (name.empty() || name.find_first_of("/\\") != std::string::npos) return bad;
      if (!seen.insert(name).second) return Status::DataError(file + ": expression " + name + " is listed twice");
      indices->expressions.push_back(name);
    }
    indices->has_expressions = true;
  }
  HF_RETURN_IF_ERROR(ReadIndexList(json, "idx_to_landmark_verts", file, &indices->landmarks));
  HF_RETURN_IF_ERROR(ReadIndexList(json, "idx_to_rigid_landmark_idx", file, &indices->rigid_landmarks));
  HF_RETURN_IF_ERROR(ReadIndexList(json, "idx_to_rigid_verts", file, &indices->rigid_vertices));
  HF_RETURN_IF_ERROR(ReadIndexList(json, "idx_to_fitting_verts", file, &indices->fitting_vertices));
  return Status::Ok();
}

Status CheckIctIndices(const IctIndices& indices, int num_vertices, const std::string& file) {
  if (!indices.landmarks.empty() && indices.landmarks.size() != 68)
    return Status::DataError(file + ": \"idx_to_landmark_verts\" has " + std::to_string(indices.landmarks.size()) +
                             " entries, expected the 68 iBUG landmarks");
  for (int i : indices.rigid_landmarks)
    if (i >= static_cast<int>(indices.landmarks.size()))
      return Status::DataError(file + ": \"idx_to_rigid_landmark_idx\" names landmark " + std::to_string(i) +
                               " of " + std::to_string(indices.landmarks.size()));
  for (const auto* list : {&indices.landmarks, &indices.rigid_vertices, &indices.fitting_vertices})
    for (int v : *list)
      if (v >= num_vertices)
        return Status::DataError(file + ": vertex index " + std::to_string(v) + " is beyond the neutral mesh's " +
                                 std::to_string(num_vertices) + " vertices");
  return Status::Ok();
}

// identity000.obj, identity001.obj, ... in order; a gap in the numbering is an
// error rather than a silently shorter model.
Status FindIdentityFiles(const fs::path& dir, std::vector<fs::path>* files) {
  std::map<int, fs::path> numbered;
  for (const fs::path& file : ListFiles(dir, {".obj"})) {
    const std::string stem = file.stem().string();
    if (stem.rfind("identity", 0) != 0) continue;
    const std::string number = stem.substr(8);
    if (number.size() < 3 || number.size() > 9 ||
        !std::all_of(number.begin(), number.end(), [](unsigned char c) { return std::isdigit(c) != 0; }))
      continue;
    const int k = std::stoi(number);
    if (!numbered.emplace(k, file).second)
      return Status::DataError(dir.string() + ": two identity files are number " + std::to_string(k));
  }
  int expected = 0;
  for (const auto& [k, file] : numbered) {
    if (k != expected) {
      char missing[32];
      std::snprintf(missing, sizeof(missing), "identity%03d.obj", expected);
      return Status::DataError(dir.string() + ": " + missing + " is missing but " + file.filename().string() +
                               " exists");
    }
    files->push_back(file);
    ++expected;
  }
  return Status::Ok();
}

// Differences of `files` to the neutral, in metres, as a Basel PCA block:
// basis [3N, K] row-major with unit columns, variance [K] = squared lengths.
Status ReadShapeDeltas(const std::vector<fs::path>& files, const ObjMesh& neutral, double scale,
                       std::vector<float>* basis, std::vector<float>* variance) {
  const size_t n3 = neutral.positions.size();
  const size_t k_count = files.size();
  basis->assign(n3 * k_count, 0.0f);
  variance->assign(k_count, 0.0f);
  std::vector<double> delta(n3);
  for (size_t k = 0; k < k_count; ++k) {
    ObjMesh shape;
    HF_RETURN_IF_ERROR(ReadObj(files[k], /*with_faces=*/false, &shape));
    if (shape.positions.size() != n3)
      return Status::DataError(files[k].filename().string() + " has " + std::to_string(shape.num_vertices()) +
                               " vertices, " + kNeutralFile + " has " + std::to_string(neutral.num_vertices()));
    double squared = 0;
    for (size_t i = 0; i < n3; ++i) {
      delta[i] = (shape.positions[i] - neutral.positions[i]) * scale;
      squared += delta[i] * delta[i];
    }
    (*variance)[k] = static_cast<float>(squared);
    // A target equal to the neutral keeps a zero column and zero variance.
    const double inverse = squared > 0 ? 1.0 / std::sqrt(squared) : 0.0;
    for (size_t i = 0; i < n3; ++i) (*basis)[i * k_count + k] = static_cast<float>(delta[i] * inverse);
  }
  return Status::Ok();
}

// The parts of the released ICT-FaceKit topology (its README's table):
// inclusive vertex and polygon ranges.
struct IctPart {
  const char* name;
  int first_vertex, last_vertex, first_polygon, last_polygon;
};
constexpr int kIctVertices = 26719;
constexpr int kIctPolygons = 26384;
constexpr IctPart kIctParts[] = {
    {"face", 0, 9408, 0, 9229},
    {"head_and_neck", 9409, 11247, 9230, 11143},
    {"mouth_socket", 11248, 13293, 11144, 13225},
    {"eye_socket_left", 13294, 13677, 13226, 13629},
    {"eye_socket_right", 13678, 14061, 13630, 14033},
    {"gums_and_tongue", 14062, 17038, 14034, 17005},
    {"teeth", 17039, 21450, 17006, 21495},
    {"eyeball_left", 21451, 23020, 21496, 23093},
    {"eyeball_right", 23021, 24590, 23094, 24691},
    {"lacrimal_fluid_left", 24591, 24794, 24692, 24854},
    {"lacrimal_fluid_right", 24795, 24998, 24855, 25017},
    {"eye_blend_left", 24999, 25022, 25018, 25032},
    {"eye_blend_right", 25023, 25046, 25033, 25047},
    {"eye_occlusion_left", 25047, 25198, 25048, 25175},
    {"eye_occlusion_right", 25199, 25350, 25176, 25303},
    {"eyelashes_left", 25351, 26034, 25304, 25843},
    {"eyelashes_right", 26035, 26718, 25844, 26383},
};

// Everything written to the file, in the layout's own shapes.
struct BaselModel {
  int num_vertices = 0;
  std::vector<float> points;                  // [3, N] row-major
  Eigen::Matrix3Xi triangles;                 // [3, T]
  std::vector<float> mean;                    // [3N]
  std::vector<float> identity_basis;          // [3N, K] row-major
  std::vector<float> identity_variance;       // [K]
  std::vector<std::string> identity_names;    // [K]
  std::vector<float> expression_basis;        // [3N, E] row-major
  std::vector<float> expression_variance;     // [E]
  std::vector<std::string> expression_names;  // [E]
  std::vector<float> uv_coords;               // [2, U] row-major
  Eigen::Matrix3Xi uv_triangles;              // [3, T] or empty
  IctIndices indices;
  std::vector<std::pair<std::string, std::vector<int>>> regions;
  std::string source;
};

H5::StrType Utf8String() {
  H5::StrType type(H5::PredType::C_S1, H5T_VARIABLE);
  type.setCset(H5T_CSET_UTF8);
  return type;
}

void WriteAttribute(H5::H5Object& object, const std::string& name, const std::string& value) {
  const H5::StrType type = Utf8String();
  H5::Attribute attribute = object.createAttribute(name, type, H5::DataSpace(H5S_SCALAR));
  attribute.write(type, value);
}

void WriteFloats(H5::H5File& file, const std::string& path, const std::vector<hsize_t>& dims, const float* values) {
  H5::DataSpace space(static_cast<int>(dims.size()), dims.data());
  H5::DataSet data = file.createDataSet(path, H5::PredType::IEEE_F32LE, space);
  data.write(values, H5::PredType::NATIVE_FLOAT);
}

void WriteInts(H5::H5File& file, const std::string& path, const std::vector<hsize_t>& dims, const int* values) {
  H5::DataSpace space(static_cast<int>(dims.size()), dims.data());
  H5::DataSet data = file.createDataSet(path, H5::PredType::STD_I32LE, space);
  data.write(values, H5::PredType::NATIVE_INT);
}

// A [3, T] index matrix as the row-major [3, T] dataset the reader expects.
void WriteCells(H5::H5File& file, const std::string& path, const Eigen::Matrix3Xi& cells) {
  const Eigen::Matrix<int, 3, Eigen::Dynamic, Eigen::RowMajor> rows = cells;
  WriteInts(file, path, {3, static_cast<hsize_t>(cells.cols())}, rows.data());
}

void WriteStrings(H5::H5File& file, const std::string& path, const std::vector<std::string>& values) {
  const H5::StrType type = Utf8String();
  const hsize_t n = values.size();
  H5::DataSpace space(1, &n);
  H5::DataSet data = file.createDataSet(path, type, space);
  std::vector<const char*> raw;
  for (const auto& s : values) raw.push_back(s.c_str());
  data.write(raw.data(), type);
}

void WritePca(H5::H5File& file, const std::string& group, const std::vector<float>& mean,
              const std::vector<float>& basis, const std::vector<float>& variance) {
  const hsize_t n3 = mean.size(), k = variance.size();
  file.createGroup(group);
  WriteFloats(file, group + "/mean", {n3}, mean.data());
  WriteFloats(file, group + "/pcaBasis", {n3, k}, basis.data());
  WriteFloats(file, group + "/pcaVariance", {k}, variance.data());
  const float zero = 0.0f;
  H5::DataSet noise = file.createDataSet(group + "/noiseVariance", H5::PredType::IEEE_F32LE, H5::DataSpace(H5S_SCALAR));
  noise.write(&zero, H5::PredType::NATIVE_FLOAT);
}

void WriteIndexList(H5::H5File& file, const std::string& path, const std::vector<int>& values) {
  WriteInts(file, path, {static_cast<hsize_t>(values.size())}, values.data());
}

Status WriteBaselModel(const fs::path& path, const BaselModel& m) {
  H5::Exception::dontPrint();
  try {
    H5::H5File file(path.string(), H5F_ACC_TRUNC);
    WriteAttribute(file, "name", "ICT-FaceKit face model");
    WriteAttribute(file, "source", m.source);
    WriteAttribute(file, "license", "MIT (ICT-FaceKit, USC Institute for Creative Technologies)");
    WriteAttribute(file, "units", "meters");
    WriteAttribute(file, "axes", "right-handed, +y up, face looks toward +z");
    WriteAttribute(file, "reconstruction",
                   "points = shape.mean + shape.pcaBasis*sqrt(shape.pcaVariance)*alpha + "
                   "expression.pcaBasis*sqrt(expression.pcaVariance)*beta; alpha ~ N(0,1) per identity mode, "
                   "beta in [0,1] per blendshape");
    const hsize_t n = static_cast<hsize_t>(m.num_vertices);

    H5::Group shape = file.createGroup("/shape");
    WriteAttribute(shape, "kind", "pca");
    file.createGroup("/shape/representer");
    WriteFloats(file, "/shape/representer/points", {3, n}, m.points.data());
    WriteCells(file, "/shape/representer/cells", m.triangles);
    WritePca(file, "/shape/model", m.mean, m.identity_basis, m.identity_variance);
    WriteStrings(file, "/shape/names", m.identity_names);

    if (!m.expression_names.empty()) {
      H5::Group expression = file.createGroup("/expression");
      WriteAttribute(expression, "kind", "blendshapes");
      const std::vector<float> zeros(m.mean.size(), 0.0f);
      WritePca(file, "/expression/model", zeros, m.expression_basis, m.expression_variance);
      WriteStrings(file, "/expression/names", m.expression_names);
    }
    if (m.uv_triangles.cols() > 0) {
      file.createGroup("/uv");
      WriteFloats(file, "/uv/coords", {2, static_cast<hsize_t>(m.uv_coords.size() / 2)}, m.uv_coords.data());
      WriteCells(file, "/uv/cells", m.uv_triangles);
    }
    if (!m.indices.landmarks.empty()) {
      file.createGroup("/landmarks");
      WriteIndexList(file, "/landmarks/ibug68", m.indices.landmarks);
      if (!m.indices.rigid_landmarks.empty())
        WriteIndexList(file, "/landmarks/ibug68_rigid", m.indices.rigid_landmarks);
    }
    if (!m.indices.rigid_vertices.empty() || !m.indices.fitting_vertices.empty()) {
      file.createGroup("/masks");
      if (!m.indices.rigid_vertices.empty()) WriteIndexList(file, "/masks/rigid_vertices", m.indices.rigid_vertices);
      if (!m.indices.fitting_vertices.empty())
        WriteIndexList(file, "/masks/fitting_vertices", m.indices.fitting_vertices);
    }
    if (!m.regions.empty()) {
      H5::Group regions = file.createGroup("/regions");
      WriteAttribute(regions, "layout", "[first_vertex, last_vertex, first_triangle, last_triangle], inclusive");
      for (const auto& [name, range] : m.regions) WriteIndexList(file, "/regions/" + name, range);
    }
    file.close();
  } catch (const H5::Exception& e) {
    return Status::IoError("cannot write " + path.string() + ": " + e.getDetailMsg());
  }
  return Status::Ok();
}

}  // namespace

Status IctImportOptions::Check() const {
  if (!(scale > 0) || !std::isfinite(scale))
    return Status::InvalidArgument("scale must be a positive number of metres per OBJ unit");
  if (max_identities < 0) return Status::InvalidArgument("max_identities must be >= 0 (0 reads all)");
  return Status::Ok();
}

Status ImportIctFaceKit(const std::string& dir, const std::string& out_path, const IctImportOptions& options,
                        IctImportSummary* summary) {
  HF_RETURN_IF_ERROR(options.Check());
  if (out_path.empty()) return Status::InvalidArgument("no output file given");
  const fs::path folder(dir);
  std::error_code ec;
  if (!fs::exists(folder, ec)) return Status::NotFound("ICT-FaceKit folder not found: " + dir);
  if (!fs::is_directory(folder, ec))
    return Status::InvalidArgument(dir + " is not a folder (give ICT-FaceKit's FaceXModel folder)");
  const fs::path neutral_path = folder / kNeutralFile;
  if (!fs::exists(neutral_path, ec))
    return Status::NotFound(dir + " has no " + kNeutralFile + " (is it ICT-FaceKit's FaceXModel folder?)");
  const fs::path indices_path = folder / kIndicesFile;
  if (!fs::exists(indices_path, ec)) return Status::NotFound(dir + " has no " + kIndicesFile);

  BaselModel m;
  HF_RETURN_IF_ERROR(ReadIctIndices(indices_path, &m.indices));
  ObjMesh neutral;
  HF_RETURN_IF_ERROR(ReadObj(neutral_path, /*with_faces=*/true, &neutral));
  if (neutral.num_polygons() == 0) return Status::DataError(neutral_path.string() + " has no faces");
  const int n = neutral.num_vertices();
  HF_RETURN_IF_ERROR(CheckIctIndices(m.indices, n, indices_path.string()));
  Triangulation topology;
  HF_RETURN_IF_ERROR(Triangulate(neutral, kNeutralFile, &topology));

  std::vector<fs::path> all_identities;
  HF_RETURN_IF_ERROR(FindIdentityFiles(folder, &all_identities));
  if (all_identities.empty())
    return Status::NotFound(dir + " has no identity shapes (identity000.obj, identity001.obj, ...)");
  std::vector<fs::path> identity_files = all_identities;
  if (options.max_identities > 0 && static_cast<int>(identity_files.size()) > options.max_identities)
    identity_files.resize(options.max_identities);

  std::vector<fs::path> expression_files;
  if (m.indices.has_expressions) {
    for (const auto& name : m.indices.expressions) {
      const fs::path file = folder / (name + ".obj");
      if (!fs::exists(file, ec))
        return Status::NotFound(kIndicesFile + std::string(" lists expression ") + name + " but " + dir +
                                " has no " + file.filename().string());
      expression_files.push_back(file);
      m.expression_names.push_back(name);
    }
  } else {
    // Without a list, every other OBJ is a blendshape, in name order.
    for (const fs::path& file : ListFiles(folder, {".obj"})) {
      if (file.filename() == kNeutralFile) continue;
      if (std::find(all_identities.begin(), all_identities.end(), file) != all_identities.end()) continue;
      expression_files.push_back(file);
      m.expression_names.push_back(file.stem().string());
    }
  }

  HF_LOG(Info) << "face-model: " << kNeutralFile << ": " << n << " vertices, " << neutral.num_polygons()
               << " polygons; reading " << identity_files.size() << " identity and " << expression_files.size()
               << " expression shapes";
  const double scale = options.scale;
  m.num_vertices = n;
  m.points.resize(3 * static_cast<size_t>(n));
  m.mean.resize(3 * static_cast<size_t>(n));
  for (int i = 0; i < n; ++i)
    for (int r = 0; r < 3; ++r) {
      const float value = static_cast<float>(neutral.positions[3 * i + r] * scale);
      m.points[static_cast<size_t>(r) * n + i] = value;
      m.mean[3 * static_cast<size_t>(i) + r] = value;
    }
  m.triangles = topology.triangles;
  HF_RETURN_IF_ERROR(ReadShapeDeltas(identity_files, neutral, scale, &m.identity_basis, &m.identity_variance));
  for (const auto& file : identity_files) m.identity_names.push_back(file.stem().string());
  HF_RETURN_IF_ERROR(
      ReadShapeDeltas(expression_files, neutral, scale, &m.expression_basis, &m.expression_variance));

  if (topology.uv_triangles.cols() > 0) {
    const size_t u = neutral.uvs.size() / 2;
    m.uv_coords.resize(2 * u);
    for (size_t i = 0; i < u; ++i) {
      m.uv_coords[i] = neutral.uvs[2 * i];
      m.uv_coords[u + i] = neutral.uvs[2 * i + 1];
    }
    m.uv_triangles = topology.uv_triangles;
  }
  if (n == kIctVertices && neutral.num_polygons() == kIctPolygons) {
    for (const IctPart& part : kIctParts)
      m.regions.push_back({part.name,
                           {part.first_vertex, part.last_vertex, topology.first_triangle[part.first_polygon],
                            topology.first_triangle[part.last_polygon + 1] - 1}});
  }
  char scale_text[32];
  std::snprintf(scale_text, sizeof(scale_text), "%g", scale);
  m.source = "ICT-FaceKit FaceXModel folder " + AbsolutePath(folder).string() + " (OBJ units x " + scale_text +
             " = metres)";

  const fs::path out(out_path);
  if (out.has_parent_path()) HF_RETURN_IF_ERROR(EnsureDirectory(out.parent_path()));
  const fs::path partial = out.string() + ".partial";
  if (Status s = WriteBaselModel(partial, m); !s.ok()) {
    RemoveAll(partial);
    return s;
  }
  if (Status s = ReplacePath(partial, out); !s.ok()) {
    RemoveAll(partial);
    return s;
  }
  if (summary) {
    summary->num_vertices = n;
    summary->num_polygons = neutral.num_polygons();
    summary->num_triangles = static_cast<int>(m.triangles.cols());
    summary->num_uvs = static_cast<int>(m.uv_coords.size() / 2);
    summary->num_identities = static_cast<int>(identity_files.size());
    summary->num_expressions = static_cast<int>(expression_files.size());
    summary->num_landmarks = static_cast<int>(m.indices.landmarks.size());
    summary->num_regions = static_cast<int>(m.regions.size());
  }
  return Status::Ok();
}

}  // namespace headforge
