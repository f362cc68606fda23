#include "export/mesh_avatar.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <unordered_map>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/photo.hpp>

#include "capture/capture_io.h"
#include "core/camera_set.h"
#include "core/log.h"
#include "core/mesh_renderer.h"
#include "core/parallel.h"
#include "export/gltf_builder.h"
#include "reconstruction/tracking_io.h"

namespace headforge {
namespace {

// Where each group of the face model's parts goes in the texture atlas
// (fractions of its width and height; glTF's v down). The atlas is square,
// so a power-of-two texture size gives a power-of-two texture. The skin
// (face, scalp and neck: two UV tiles side by side) takes the top half; the
// eyes (both on one chart), teeth, gums and mouth share the bottom half. The
// eyelashes and the eyes' occlusion and tear shells are left out, as they
// are for the Gaussians.
struct AtlasSlot {
  std::vector<const char*> regions;
  float x, y, w, h;
};
const AtlasSlot kSlots[] = {
    {{"face", "head_and_neck"}, 0.0f, 0.0f, 1.0f, 0.5f},
    {{"eyeball_left", "eyeball_right"}, 0.0f, 0.5f, 0.5f, 0.5f},
    {{"teeth"}, 0.5f, 0.5f, 0.25f, 0.25f},
    {{"gums_and_tongue"}, 0.75f, 0.5f, 0.25f, 0.25f},
    {{"mouth_socket"}, 0.5f, 0.75f, 0.25f, 0.25f},
};
constexpr int kSlotMargin = 4;  // texels kept free round each slot so lookups do not bleed

struct Atlas {
  cv::Size size;
  Eigen::Matrix3Xi triangles;     // into the split vertices
  std::vector<int> source_vertex;
  Eigen::Matrix2Xf texcoords;     // glTF convention
};

// Splits the face model's vertices where its UVs are discontinuous and maps
// each chosen part's UVs into its atlas slot.
Status BuildAtlas(const FaceModel& model, int texture_size, Atlas* atlas) {
  if (!model.has_uv()) return Status::DataError("the face model " + model.path() + " has no UVs to bake a texture onto");
  atlas->size = cv::Size(2 * texture_size, 2 * texture_size);
  std::unordered_map<int64_t, int> split;
  std::vector<Eigen::Vector3i> triangles;
  std::vector<Eigen::Vector2f> texcoords;
  for (size_t s = 0; s < std::size(kSlots); ++s) {
    const AtlasSlot& slot = kSlots[s];
    std::vector<int> tris;
    for (const char* name : slot.regions)
      if (const FaceModel::Region* r = model.FindRegion(name))
        for (int t = r->first_triangle; t <= r->last_triangle; ++t) tris.push_back(t);
    if (tris.empty()) continue;
    Eigen::Vector2f lo(1e9f, 1e9f), hi(-1e9f, -1e9f);
    for (int t : tris)
      for (int k = 0; k < 3; ++k) {
        const Eigen::Vector2f uv = model.uv_coords().col(model.uv_triangles()(k, t));
        lo = lo.cwiseMin(uv);
        hi = hi.cwiseMax(uv);
      }
    const Eigen::Vector2f span = (hi - lo).cwiseMax(1e-6f);
    const float mx = float(kSlotMargin) / atlas->size.width, my = float(kSlotMargin) / atlas->size.height;
    for (int t : tris) {
      Eigen::Vector3i tri;
      for (int k = 0; k < 3; ++k) {
        const int v = model.triangles()(k, t), u = model.uv_triangles()(k, t);
        const int64_t key = (int64_t(v) << 32) | (int64_t(u) << 3) | int64_t(s);
        auto [it, added] = split.emplace(key, int(texcoords.size()));
        if (added) {
          const Eigen::Vector2f uv = model.uv_coords().col(u);
          const float a = (uv.x() - lo.x()) / span.x(), b = 1.0f - (uv.y() - lo.y()) / span.y();
          texcoords.emplace_back(slot.x + mx + a * (slot.w - 2 * mx), slot.y + my + b * (slot.h - 2 * my));
          atlas->source_vertex.push_back(v);
        }
        tri[k] = it->second;
      }
      triangles.push_back(tri);
    }
  }
  atlas->triangles.resize(3, Eigen::Index(triangles.size()));
  for (size_t t = 0; t < triangles.size(); ++t) atlas->triangles.col(Eigen::Index(t)) = triangles[t];
  atlas->texcoords.resize(2, Eigen::Index(texcoords.size()));
  for (size_t i = 0; i < texcoords.size(); ++i) atlas->texcoords.col(Eigen::Index(i)) = texcoords[i];
  return Status::Ok();
}

Eigen::Matrix3Xf Gather(const Eigen::Matrix3Xf& vertices, const std::vector<int>& source) {
  Eigen::Matrix3Xf out(3, Eigen::Index(source.size()));
  for (size_t i = 0; i < source.size(); ++i) out.col(Eigen::Index(i)) = vertices.col(source[i]);
  return out;
}

// One frame as the baking sees it: the image (distortion removed), its mask,
// the pinhole and the head's vertices in that camera's world.
struct BakeView {
  cv::Mat image, mask;
  PinholeCamera camera;
  Eigen::Matrix3Xf vertices;  // split vertices, posed
};

Status ReadBakeView(const IngestedCapture& capture, const std::string& camera, const CameraIntrinsics& lens, int frame,
                    BakeView* view) {
  HF_RETURN_IF_ERROR(ReadUndistortedFrame(capture, camera, lens, frame, &view->image, &view->mask));
  // The mask's edge holds background at grazing angles: keep clear of it.
  const int erode = std::max(1, view->mask.cols / 128);
  cv::erode(view->mask, view->mask, cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(2 * erode + 1, 2 * erode + 1)));
  view->camera.fx = lens.fx;
  view->camera.fy = lens.fy > 0 ? lens.fy : lens.fx;
  view->camera.cx = lens.cx;
  view->camera.cy = lens.cy;
  view->camera.width = view->image.cols;
  view->camera.height = view->image.rows;
  return Status::Ok();
}

cv::Vec3f Bilinear(const cv::Mat& image, double x, double y) {
  const int x0 = std::clamp(int(std::floor(x)), 0, image.cols - 2), y0 = std::clamp(int(std::floor(y)), 0, image.rows - 2);
  const float ax = float(std::clamp(x - x0, 0.0, 1.0)), ay = float(std::clamp(y - y0, 0.0, 1.0));
  const auto at = [&](int yy, int xx) { return cv::Vec3f(image.at<cv::Vec3b>(yy, xx)); };
  return (at(y0, x0) * (1 - ax) + at(y0, x0 + 1) * ax) * (1 - ay) + (at(y0 + 1, x0) * (1 - ax) + at(y0 + 1, x0 + 1) * ax) * ay;
}

// Adds what `view` sees of each texel to the running sums.
void BakeOne(const BakeView& view, const Atlas& atlas, const std::vector<TexelHit>& hits, cv::Mat* sum, cv::Mat* weight) {
  Mesh mesh;
  mesh.vertices = view.vertices;
  mesh.triangles = atlas.triangles;
  mesh.materials.emplace_back();
  RenderOutput rendered;
  RenderOptions options;
  options.supersample = 1;
  RenderMeshes({&mesh}, view.camera, options, &rendered);
  const Eigen::Matrix3d r = view.camera.cam_from_world.linear();
  const Eigen::Vector3d t = view.camera.cam_from_world.translation(), centre = view.camera.Centre();
  const int width = atlas.size.width;
  ParallelFor(atlas.size.height, DefaultThreads(), [&](int y, int) {
    for (int x = 0; x < width; ++x) {
      const TexelHit& hit = hits[size_t(y) * size_t(width) + size_t(x)];
      if (hit.triangle < 0) continue;
      Eigen::Vector3d p = Eigen::Vector3d::Zero(), corners[3];
      for (int k = 0; k < 3; ++k) {
        corners[k] = view.vertices.col(atlas.triangles(k, hit.triangle)).cast<double>();
        p += double(hit.bary[k]) * corners[k];
      }
      const Eigen::Vector3d normal = (corners[1] - corners[0]).cross(corners[2] - corners[0]);
      const Eigen::Vector3d to_camera = centre - p;
      const double cosine = normal.dot(to_camera) / std::max(normal.norm() * to_camera.norm(), 1e-12);
      if (cosine < 0.3) continue;  // grazing views smear and catch the background
      const Eigen::Vector3d q = r * p + t;
      if (q.z() < 0.01) continue;
      const double u = view.camera.fx * q.x() / q.z() + view.camera.cx, v = view.camera.fy * q.y() / q.z() + view.camera.cy;
      const int pu = int(std::lround(u)), pv = int(std::lround(v));
      if (pu < 1 || pv < 1 || pu >= view.image.cols - 1 || pv >= view.image.rows - 1) continue;
      const float depth = rendered.depth.at<float>(pv, pu);
      if (depth <= 0 || std::abs(depth - q.z()) > 0.004) continue;  // hidden behind another part
      if (view.mask.at<uint8_t>(pv, pu) < 128) continue;
      const float w = float(cosine * cosine);
      sum->at<cv::Vec3f>(y, x) += Bilinear(view.image, u, v) * w;
      weight->at<float>(y, x) += w;
    }
  });
}

}  // namespace

std::string ArkitName(const std::string& name) {
  const auto ends = [&](const char* suffix) {
    return name.size() > 2 && name.compare(name.size() - 2, 2, suffix) == 0;
  };
  if (ends("_L")) return name.substr(0, name.size() - 2) + "Left";
  if (ends("_R")) return name.substr(0, name.size() - 2) + "Right";
  return name;
}

Status BuildMeshAvatar(const fs::path& workspace, const FaceModel& model, const MeshAvatarOptions& options,
                       Progress* progress, MeshAvatar* avatar) {
  if (options.texture_size < 16 || options.texture_size > 8192)
    return Status::InvalidArgument("the texture size must lie in [16, 8192] texels, not " +
                                   std::to_string(options.texture_size));
  IngestedCapture capture;
  CameraSet cameras;
  TrackingFile tracking;
  HF_RETURN_IF_ERROR(ReadTrackedWorkspace(workspace, model, &capture, &cameras, &tracking));
  Atlas atlas;
  HF_RETURN_IF_ERROR(BuildAtlas(model, options.texture_size, &atlas));

  MeshAvatar out;
  const Eigen::Matrix3Xf identity = model.Identity(tracking.identity.cast<float>());
  out.positions = Gather(identity, atlas.source_vertex);
  out.triangles = atlas.triangles;
  out.texcoords = atlas.texcoords;
  out.source_vertex = atlas.source_vertex;
  const Eigen::MatrixXf& basis = model.expression_basis();
  for (int e = 0; e < model.num_expressions(); ++e) {
    Eigen::Matrix3Xf offsets(3, Eigen::Index(atlas.source_vertex.size()));
    for (size_t i = 0; i < atlas.source_vertex.size(); ++i)
      for (int d = 0; d < 3; ++d) offsets(d, Eigen::Index(i)) = basis(3 * atlas.source_vertex[i] + d, e);
    out.targets.push_back(offsets);
    out.target_names.push_back(ArkitName(model.expression_names()[size_t(e)]));
  }
  const IngestedCamera& first = capture.cameras.front();
  const CameraIntrinsics* lens0 = cameras.FindCamera(first.name);
  const CameraView* view0 = nullptr;
  for (const CameraView& v : cameras.views)
    if (v.camera == first.name && v.registered && !view0) view0 = &v;
  if (!lens0 || !view0) return Status::DataError("cameras_head.json has no registered view of " + first.name +
                                                 "; run headforge align again");
  for (const TrackedFrame& f : tracking.frames) {
    out.weights.push_back(f.expression.cast<float>());
    // A fixed camera (head-pose cameras, one per frame, each carrying the
    // head's motion as PnP saw it): seen from the first view's camera held
    // still, the head moves by C0^-1 C_k H_k. A moving camera round a still
    // head: the head moves by H_k alone.
    const CameraView* view = cameras.FindView(first.name, f.frame);
    if (cameras.mode == "head-pose" && view && view->registered)
      out.head_motion.push_back(view0->cam_from_world.inverse() * view->cam_from_world * f.head_motion);
    else
      out.head_motion.push_back(f.head_motion);
    const double t = f.frame < int(first.frames.size()) ? first.frames[size_t(f.frame)].time_s : 0.0;
    out.times.push_back(t - first.frames.front().time_s);
  }
  // Times must rise strictly; frames without a usable time get the video's rate.
  for (size_t i = 1; i < out.times.size(); ++i)
    if (!(out.times[i] > out.times[i - 1])) out.times[i] = out.times[i - 1] + 1.0 / std::max(first.source_fps, 1.0);

  out.width = first.width;
  out.height = first.height;
  out.aspect = double(first.width) / first.height;
  out.yfov = 2 * std::atan(0.5 * first.height / (lens0->fy > 0 ? lens0->fy : lens0->fx));
  // The viewer's camera is the first view's (with head-pose cameras it then
  // sees every frame as the capture's camera did).
  out.cam_from_world = view0->cam_from_world;

  // The views to bake from: reliable frames spread over the capture, every camera.
  std::vector<std::pair<const IngestedCamera*, int>> bake;
  std::vector<int> reliable;
  for (const TrackedFrame& f : tracking.frames)
    if (!f.interpolated && !f.low_confidence) reliable.push_back(f.frame);
  if (reliable.empty()) {
    // A walk-around whose head is held still is flagged all over (the
    // detector's landmarks on its sides), though its cameras place it well.
    for (const TrackedFrame& f : tracking.frames) reliable.push_back(f.frame);
    if (reliable.empty()) return Status::DataError("the tracking has no frames; nothing to bake a texture from");
    HF_LOG(Warning) << "export mesh: every tracked frame is flagged unreliable (tracking.json); the texture is baked "
                       "from frames spread over the whole capture instead";
  }
  const int per_camera = std::max(1, options.bake_views / int(capture.cameras.size()));
  for (const IngestedCamera& cam : capture.cameras)
    for (int k = 0; k < std::min<int>(per_camera, int(reliable.size())); ++k)
      bake.emplace_back(&cam, reliable[size_t(k) * reliable.size() / size_t(std::min<int>(per_camera, int(reliable.size())))]);

  std::vector<int> all(size_t(out.triangles.cols()));
  for (size_t t = 0; t < all.size(); ++t) all[t] = int(t);
  Eigen::Matrix2Xf texels(2, out.texcoords.cols());
  for (Eigen::Index i = 0; i < texels.cols(); ++i)
    texels.col(i) = Eigen::Vector2f(out.texcoords(0, i) * atlas.size.width - 0.5f, out.texcoords(1, i) * atlas.size.height - 0.5f);
  const std::vector<TexelHit> hits = RasteriseTexels(texels, out.triangles, all, atlas.size);
  cv::Mat sum(atlas.size, CV_32FC3, cv::Scalar::all(0)), weight(atlas.size, CV_32F, cv::Scalar(0));
  progress->Start("bake texture", int64_t(bake.size()));
  for (const auto& [cam, frame] : bake) {
    const CameraIntrinsics* lens = cameras.FindCamera(cam->name);
    const CameraView* registered = cameras.FindView(cam->name, frame);
    progress->Advance();
    if (!lens || !registered || !registered->registered) continue;
    BakeView view;
    HF_RETURN_IF_ERROR(ReadBakeView(capture, cam->name, *lens, frame, &view));
    const TrackedFrame& tracked = tracking.frames[size_t(frame)];
    Eigen::Matrix3Xf posed = identity;
    model.AddExpression(tracked.expression.cast<float>(), &posed);
    view.vertices = Gather(posed, atlas.source_vertex);
    view.camera.cam_from_world = registered->cam_from_world * tracked.head_motion;
    BakeOne(view, atlas, hits, &sum, &weight);
  }
  progress->Finish();

  // Seen texels get their weighted mean; texels on the mesh no view saw are
  // filled in from the seen ones round them; the margins round the charts
  // are padded so lookups along seams find colour.
  cv::Mat colour(atlas.size, CV_8UC3, cv::Scalar::all(0));
  cv::Mat seen(atlas.size, CV_8U, cv::Scalar(0)), on_mesh(atlas.size, CV_8U, cv::Scalar(0));
  for (int y = 0; y < atlas.size.height; ++y)
    for (int x = 0; x < atlas.size.width; ++x) {
      if (hits[size_t(y) * size_t(atlas.size.width) + size_t(x)].triangle >= 0) on_mesh.at<uint8_t>(y, x) = 255;
      const float w = weight.at<float>(y, x);
      if (w <= 0) continue;
      const cv::Vec3f c = sum.at<cv::Vec3f>(y, x) / w;
      colour.at<cv::Vec3b>(y, x) = cv::Vec3b(cv::saturate_cast<uint8_t>(c[0]), cv::saturate_cast<uint8_t>(c[1]),
                                             cv::saturate_cast<uint8_t>(c[2]));
      seen.at<uint8_t>(y, x) = 255;
    }
  if (cv::countNonZero(seen) == 0) return Status::DataError("no frame saw the head's surface; the texture cannot be baked");
  const cv::Mat holes = on_mesh & ~seen;
  if (cv::countNonZero(holes) > 0) {
    // Inpainting works at a quarter size (large holes such as the back of the
    // head would take minutes at full size), and the result fills the holes.
    cv::Mat small, small_holes, filled_small, filled;
    cv::resize(colour, small, atlas.size / 4, 0, 0, cv::INTER_AREA);
    cv::resize(holes, small_holes, atlas.size / 4, 0, 0, cv::INTER_NEAREST);
    cv::Mat small_seen;
    cv::resize(seen, small_seen, atlas.size / 4, 0, 0, cv::INTER_AREA);
    small_holes = small_holes | (small_seen < 255);
    cv::inpaint(small, small_holes, filled_small, 3, cv::INPAINT_TELEA);
    cv::resize(filled_small, filled, atlas.size, 0, 0, cv::INTER_LINEAR);
    filled.copyTo(colour, holes);
  }
  cv::Mat padded = on_mesh | seen;
  PadSeams(&colour, &padded, 2 * kSlotMargin);
  out.texture = colour;
  out.texture_seen = seen;
  *avatar = std::move(out);
  return Status::Ok();
}

Eigen::Matrix3Xf MeshAvatarVertices(const MeshAvatar& avatar, int frame) {
  Eigen::Matrix3Xf v = avatar.positions;
  const Eigen::VectorXf& w = avatar.weights[size_t(frame)];
  for (size_t e = 0; e < avatar.targets.size(); ++e)
    if (w[Eigen::Index(e)] != 0) v += w[Eigen::Index(e)] * avatar.targets[e];
  const Eigen::Isometry3f motion = avatar.head_motion[size_t(frame)].cast<float>();
  return (motion.linear() * v).colwise() + motion.translation();
}

Status WriteMeshAvatarGlb(const fs::path& path, const MeshAvatar& avatar) {
  GltfBuilder gltf;
  tinygltf::Model& m = gltf.model();
  const auto floats = [](const auto& matrix) {
    return std::vector<float>(matrix.data(), matrix.data() + matrix.size());
  };
  tinygltf::Primitive primitive;
  primitive.mode = TINYGLTF_MODE_TRIANGLES;
  primitive.attributes["POSITION"] = gltf.Floats(floats(avatar.positions), 3, true, TINYGLTF_TARGET_ARRAY_BUFFER);
  primitive.attributes["TEXCOORD_0"] = gltf.Floats(floats(avatar.texcoords), 2, false, TINYGLTF_TARGET_ARRAY_BUFFER);
  std::vector<uint32_t> indices(avatar.triangles.data(), avatar.triangles.data() + avatar.triangles.size());
  primitive.indices = gltf.Indices(indices);
  // Each blendshape moves a part of the head: sparse targets hold only the
  // vertices moved by more than a micrometre (about a quarter of them).
  for (const Eigen::Matrix3Xf& target : avatar.targets)
    primitive.targets.push_back({{"POSITION", gltf.SparseVec3(floats(target))}});

  // The texture: a PNG in the buffer, shown unlit (the frames' light is baked in).
  std::vector<unsigned char> png;
  if (!cv::imencode(".png", avatar.texture, png)) return Status::Internal("cannot encode the texture as PNG");
  tinygltf::Texture texture;
  texture.source = gltf.PngImage(png, "skin");
  tinygltf::Sampler sampler;
  sampler.magFilter = TINYGLTF_TEXTURE_FILTER_LINEAR;
  sampler.minFilter = TINYGLTF_TEXTURE_FILTER_LINEAR_MIPMAP_LINEAR;
  sampler.wrapS = sampler.wrapT = TINYGLTF_TEXTURE_WRAP_CLAMP_TO_EDGE;
  m.samplers.push_back(sampler);
  texture.sampler = 0;
  m.textures.push_back(texture);
  tinygltf::Material material;
  material.name = "baked";
  material.pbrMetallicRoughness.baseColorTexture.index = 0;
  material.pbrMetallicRoughness.metallicFactor = 0;
  material.pbrMetallicRoughness.roughnessFactor = 1;
  material.extensions["KHR_materials_unlit"] = tinygltf::Value(tinygltf::Value::Object());
  m.materials.push_back(material);
  m.extensionsUsed.push_back("KHR_materials_unlit");
  primitive.material = 0;

  tinygltf::Mesh mesh;
  mesh.name = "head";
  mesh.primitives.push_back(primitive);
  mesh.weights.assign(avatar.targets.size(), 0.0);
  tinygltf::Value::Array names;
  for (const std::string& n : avatar.target_names) names.emplace_back(n);
  mesh.extras = tinygltf::Value(tinygltf::Value::Object{{"targetNames", tinygltf::Value(names)}});
  m.meshes.push_back(mesh);

  tinygltf::Node head;
  head.name = "head";
  head.mesh = 0;
  m.nodes.push_back(head);

  // The camera: OpenCV's looks down +z with +y down; glTF's down -z with +y up.
  tinygltf::Camera camera;
  camera.type = "perspective";
  camera.perspective.yfov = avatar.yfov;
  camera.perspective.aspectRatio = avatar.aspect;
  camera.perspective.znear = 0.01;
  camera.perspective.zfar = 100;
  m.cameras.push_back(camera);
  Eigen::Isometry3d world_from_camera = avatar.cam_from_world.inverse();
  world_from_camera.linear() = world_from_camera.linear() * Eigen::Vector3d(1, -1, -1).asDiagonal();
  const Eigen::Quaterniond cq(world_from_camera.linear());
  tinygltf::Node camera_node;
  camera_node.name = "capture_camera";
  camera_node.camera = 0;
  camera_node.rotation = {cq.x(), cq.y(), cq.z(), cq.w()};
  camera_node.translation = {world_from_camera.translation().x(), world_from_camera.translation().y(),
                             world_from_camera.translation().z()};
  m.nodes.push_back(camera_node);

  tinygltf::Scene scene;
  scene.name = "avatar";
  scene.nodes = {0, 1};
  m.scenes.push_back(scene);
  m.defaultScene = 0;

  // The tracked sequence: morph weights, rotation and translation per frame,
  // stepped at the frames' times.
  if (!avatar.times.empty()) {
    std::vector<float> times(avatar.times.begin(), avatar.times.end()), weights, rotations, translations;
    for (size_t f = 0; f < avatar.times.size(); ++f) {
      for (Eigen::Index e = 0; e < avatar.weights[f].size(); ++e) weights.push_back(avatar.weights[f][e]);
      Eigen::Quaterniond q(avatar.head_motion[f].linear());
      q.normalize();
      if (f > 0 && rotations.size() >= 4) {
        // Keep neighbouring quaternions in one hemisphere so interpolation takes the short way.
        const size_t p = rotations.size() - 4;
        if (q.x() * rotations[p] + q.y() * rotations[p + 1] + q.z() * rotations[p + 2] + q.w() * rotations[p + 3] < 0)
          q.coeffs() = -q.coeffs();
      }
      rotations.insert(rotations.end(), {float(q.x()), float(q.y()), float(q.z()), float(q.w())});
      const Eigen::Vector3d t = avatar.head_motion[f].translation();
      translations.insert(translations.end(), {float(t.x()), float(t.y()), float(t.z())});
    }
    tinygltf::Animation animation;
    animation.name = "tracked";
    const int input = gltf.Floats(times, 1, true);
    const std::pair<std::string, int> channels[] = {{"weights", gltf.Floats(weights, 1, false)},
                                                    {"rotation", gltf.Floats(rotations, 4, false)},
                                                    {"translation", gltf.Floats(translations, 3, false)}};
    for (const auto& [path_name, output] : channels) {
      tinygltf::AnimationSampler s;
      s.input = input;
      s.output = output;
      s.interpolation = "LINEAR";
      animation.samplers.push_back(s);
      tinygltf::AnimationChannel c;
      c.sampler = int(animation.samplers.size()) - 1;
      c.target_node = 0;
      c.target_path = path_name;
      animation.channels.push_back(c);
    }
    m.animations.push_back(animation);
  }
  return gltf.WriteGlb(path);
}

}  // namespace headforge
