#include "core/face_model.h"

#include <H5Cpp.h>

#include "core/fs.h"

namespace headforge {
namespace {

bool Exists(const H5::H5File& file, const std::string& path) {
  // H5Lexists checks one link at a time: walk the path's components.
  std::string prefix;
  size_t start = 1;
  while (start <= path.size()) {
    const size_t end = path.find('/', start);
    prefix = path.substr(0, end);
    if (H5Lexists(file.getId(), prefix.c_str(), H5P_DEFAULT) <= 0) return false;
    if (end == std::string::npos) break;
    start = end + 1;
  }
  return true;
}

std::vector<hsize_t> Shape(const H5::DataSet& data) {
  const H5::DataSpace space = data.getSpace();
  std::vector<hsize_t> dims(space.getSimpleExtentNdims());
  space.getSimpleExtentDims(dims.data());
  return dims;
}

// Reads a numeric dataset as row-major values of type T.
template <typename T>
std::vector<T> ReadValues(const H5::H5File& file, const std::string& path, std::vector<hsize_t>* dims) {
  const H5::DataSet data = file.openDataSet(path);
  *dims = Shape(data);
  hsize_t total = 1;
  for (hsize_t d : *dims) total *= d;
  std::vector<T> values(total);
  if (total > 0)
    data.read(values.data(), std::is_same<T, float>::value ? H5::PredType::NATIVE_FLOAT
                                                           : H5::PredType::NATIVE_INT);
  return values;
}

std::vector<std::string> ReadStrings(const H5::H5File& file, const std::string& path) {
  const H5::DataSet data = file.openDataSet(path);
  const auto dims = Shape(data);
  const hsize_t n = dims.empty() ? 1 : dims[0];
  std::vector<std::string> out;
  const H5::DataType type = data.getDataType();
  if (type.isVariableStr()) {
    std::vector<char*> raw(n, nullptr);
    const H5::StrType str = data.getStrType();  // keeps the file's character set
    data.read(raw.data(), str);
    for (auto* s : raw) out.emplace_back(s ? s : "");
    H5::DataSet::vlenReclaim(raw.data(), str, data.getSpace());
  } else {
    const size_t size = type.getSize();
    std::vector<char> raw(n * size);
    data.read(raw.data(), data.getStrType());
    for (hsize_t i = 0; i < n; ++i) {
      std::string s(raw.data() + i * size, size);
      s.erase(s.find_last_not_of(std::string("\0 ", 2)) + 1);
      out.push_back(s);
    }
  }
  return out;
}

// A [3, N] (or [N, 3]) dataset as a 3 x N matrix.
template <typename Matrix, typename T>
Status Read3xN(const H5::H5File& file, const std::string& path, int rows, Matrix* out) {
  std::vector<hsize_t> dims;
  const std::vector<T> v = ReadValues<T>(file, path, &dims);
  if (dims.size() != 2) return Status::DataError(path + " is not a matrix");
  if (static_cast<int>(dims[0]) == rows) {
    out->resize(rows, static_cast<int>(dims[1]));
    for (int r = 0; r < rows; ++r)
      for (hsize_t c = 0; c < dims[1]; ++c) (*out)(r, c) = v[r * dims[1] + c];
  } else if (static_cast<int>(dims[1]) == rows) {
    out->resize(rows, static_cast<int>(dims[0]));
    for (hsize_t c = 0; c < dims[0]; ++c)
      for (int r = 0; r < rows; ++r) (*out)(r, c) = v[c * rows + r];
  } else {
    return Status::DataError(path + " has shape [" + std::to_string(dims[0]) + ", " +
                             std::to_string(dims[1]) + "], expected " + std::to_string(rows) + " rows");
  }
  return Status::Ok();
}

// mean [3N], basis [3N, K] scaled by sqrt(variance) column-wise.
Status ReadPca(const H5::H5File& file, const std::string& group, int n3, Eigen::VectorXf* mean,
               Eigen::MatrixXf* basis) {
  std::vector<hsize_t> dm, db, dv;
  const auto m = ReadValues<float>(file, group + "/mean", &dm);
  const auto b = ReadValues<float>(file, group + "/pcaBasis", &db);
  const auto var = ReadValues<float>(file, group + "/pcaVariance", &dv);
  if (static_cast<int>(m.size()) != n3) return Status::DataError(group + "/mean does not match the vertex count");
  if (db.size() != 2 || static_cast<int>(db[0]) != n3 || db[1] != var.size())
    return Status::DataError(group + "/pcaBasis does not match mean and pcaVariance");
  *mean = Eigen::Map<const Eigen::VectorXf>(m.data(), n3);
  const int k = static_cast<int>(db[1]);
  basis->resize(n3, k);
  for (int r = 0; r < n3; ++r)
    for (int c = 0; c < k; ++c) (*basis)(r, c) = b[static_cast<size_t>(r) * k + c] * std::sqrt(std::max(0.0f, var[c]));
  return Status::Ok();
}

std::vector<int> ReadIndices(const H5::H5File& file, const std::string& path) {
  std::vector<hsize_t> dims;
  return ReadValues<int>(file, path, &dims);
}

}  // namespace

Status FaceModel::Load(const std::string& path, FaceModel* model) {
  HF_RETURN_IF_ERROR(CheckReadableFile(path, "face model"));
  H5::Exception::dontPrint();
  try {
    if (!H5::H5File::isHdf5(path)) return Status::DataError(path + " is not an HDF5 file");
    H5::H5File file(path, H5F_ACC_RDONLY);
    FaceModel m;
    m.path_ = path;
    for (const char* required : {"/shape/representer/points", "/shape/representer/cells",
                                 "/shape/model/mean", "/shape/model/pcaBasis", "/shape/model/pcaVariance"})
      if (!Exists(file, required))
        return Status::DataError(path + " lacks " + required + " (not a Basel-layout face model)");
    HF_RETURN_IF_ERROR((Read3xN<Eigen::Matrix3Xf, float>(file, "/shape/representer/points", 3, &m.neutral_)));
    HF_RETURN_IF_ERROR((Read3xN<Eigen::Matrix3Xi, int>(file, "/shape/representer/cells", 3, &m.triangles_)));
    const int n3 = 3 * m.num_vertices();
    HF_RETURN_IF_ERROR(ReadPca(file, "/shape/model", n3, &m.shape_mean_, &m.identity_basis_));
    if (Exists(file, "/expression/model/pcaBasis")) {
      HF_RETURN_IF_ERROR(ReadPca(file, "/expression/model", n3, &m.expression_mean_, &m.expression_basis_));
      if (Exists(file, "/expression/names")) m.expression_names_ = ReadStrings(file, "/expression/names");
      while (static_cast<int>(m.expression_names_.size()) < m.num_expressions())
        m.expression_names_.push_back("expression" + std::to_string(m.expression_names_.size()));
    } else {
      m.expression_mean_ = Eigen::VectorXf::Zero(n3);
      m.expression_basis_.resize(n3, 0);
    }
    if (m.triangles_.minCoeff() < 0 || m.triangles_.maxCoeff() >= m.num_vertices())
      return Status::DataError(path + ": a triangle names a vertex that does not exist");
    if (Exists(file, "/uv/coords") && Exists(file, "/uv/cells")) {
      HF_RETURN_IF_ERROR((Read3xN<Eigen::Matrix2Xf, float>(file, "/uv/coords", 2, &m.uv_coords_)));
      HF_RETURN_IF_ERROR((Read3xN<Eigen::Matrix3Xi, int>(file, "/uv/cells", 3, &m.uv_triangles_)));
      if (m.uv_triangles_.cols() != m.triangles_.cols())
        return Status::DataError(path + ": uv/cells and the mesh's cells differ in count");
    }
    if (Exists(file, "/landmarks/ibug68")) m.landmarks_ = ReadIndices(file, "/landmarks/ibug68");
    if (Exists(file, "/landmarks/ibug68_rigid")) m.rigid_landmarks_ = ReadIndices(file, "/landmarks/ibug68_rigid");
    if (Exists(file, "/masks/rigid_vertices")) m.rigid_vertices_ = ReadIndices(file, "/masks/rigid_vertices");
    if (Exists(file, "/masks/fitting_vertices")) m.fitting_vertices_ = ReadIndices(file, "/masks/fitting_vertices");
    for (int v : m.landmarks_)
      if (v < 0 || v >= m.num_vertices()) return Status::DataError(path + ": landmark vertex out of range");
    if (Exists(file, "/regions")) {
      const H5::Group regions = file.openGroup("/regions");
      for (hsize_t i = 0; i < regions.getNumObjs(); ++i) {
        const std::string name = regions.getObjnameByIdx(i);
        const auto r = ReadIndices(file, "/regions/" + name);
        if (r.size() != 4) return Status::DataError(path + ": region " + name + " is not 4 indices");
        m.regions_[name] = Region{r[0], r[1], r[2], r[3]};
      }
    }
    *model = std::move(m);
  } catch (const H5::Exception& e) {
    return Status::DataError("cannot read face model " + path + ": " + e.getDetailMsg());
  }
  return Status::Ok();
}

Eigen::Matrix3Xf FaceModel::Identity(const Eigen::VectorXf& alpha) const {
  HF_CHECK(alpha.size() <= num_identity());
  Eigen::VectorXf flat = shape_mean_;
  if (alpha.size() > 0) flat.noalias() += identity_basis_.leftCols(alpha.size()) * alpha;
  return Eigen::Map<const Eigen::Matrix3Xf>(flat.data(), 3, num_vertices());
}

void FaceModel::AddExpression(const Eigen::VectorXf& beta, Eigen::Matrix3Xf* vertices) const {
  HF_CHECK(beta.size() <= num_expressions());
  HF_CHECK(vertices->cols() == num_vertices());
  Eigen::Map<Eigen::VectorXf> flat(vertices->data(), 3 * num_vertices());
  flat += expression_mean_;
  if (beta.size() > 0) flat.noalias() += expression_basis_.leftCols(beta.size()) * beta;
}

Eigen::Matrix3Xf FaceModel::Vertices(const Eigen::VectorXf& alpha, const Eigen::VectorXf& beta) const {
  Eigen::Matrix3Xf v = Identity(alpha);
  AddExpression(beta, &v);
  return v;
}

int FaceModel::ExpressionIndex(const std::string& name) const {
  for (size_t i = 0; i < expression_names_.size(); ++i)
    if (expression_names_[i] == name) return static_cast<int>(i);
  return -1;
}

const FaceModel::Region* FaceModel::FindRegion(const std::string& name) const {
  const auto it = regions_.find(name);
  return it == regions_.end() ? nullptr : &it->second;
}

}  // namespace headforge
