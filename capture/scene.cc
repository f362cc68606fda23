#include "capture/scene.h"

#include <toml++/toml.h>

#include <algorithm>
#include <cmath>

#include "core/fs.h"

namespace headforge {

const std::vector<std::string>& KnownEffects() {
  static const std::vector<std::string> effects = {
      "lighting",        "motion_blur",         "rolling_shutter", "occlusion",
      "lens_distortion", "defocus_blur",        "exposure_drift",  "white_balance_drift",
      "sensor_noise",    "video_compression"};
  return effects;
}

double SceneIntrinsics::fx() const {
  if (focal > 0) return focal;
  return 0.5 * width / std::tan(0.5 * fov_deg * 3.14159265358979323846 / 180.0);
}

int Scene::FrameCount() const {
  if (frames > 0) return frames;
  return std::max(1, static_cast<int>(std::lround(duration * fps)));
}

bool Scene::HasEffect(const std::string& name) const {
  return std::find(effects.begin(), effects.end(), name) != effects.end();
}

double Scene::Param(const std::string& effect, const std::string& key, double fallback) const {
  const auto e = effect_params.find(effect);
  if (e == effect_params.end()) return fallback;
  const auto p = e->second.find(key);
  return p == e->second.end() ? fallback : p->second;
}

Status Scene::Check() const {
  if (!(fps > 0)) return Status::InvalidArgument("fps must be positive");
  if (!(duration > 0) && frames <= 0) return Status::InvalidArgument("duration must be positive");
  if (supersample < 1 || supersample > 8) return Status::InvalidArgument("render.supersample must be in [1, 8]");
  const auto& in = camera.intrinsics;
  if (in.width <= 0 || in.height <= 0 || in.width > 8192 || in.height > 8192)
    return Status::InvalidArgument("camera.intrinsics width and height must be in [1, 8192]");
  if (!(in.fx() > 0)) return Status::InvalidArgument("camera.intrinsics focal (or fov_deg) must be positive");
  const std::vector<std::string> rigs = {"static", "orbit", "rig", "handheld"};
  if (std::find(rigs.begin(), rigs.end(), camera.rig) == rigs.end())
    return Status::InvalidArgument("camera.rig must be static, orbit, rig or handheld, not '" + camera.rig + "'");
  if (camera.rig == "rig" && camera.positions.empty() && camera.count < 1)
    return Status::InvalidArgument("camera.count must be at least 1");
  if (camera.rig == "orbit" && camera.elevations.empty())
    return Status::InvalidArgument("camera.elevations needs at least one ring");
  const std::vector<std::string> backgrounds = {"flat", "backdrop", "room"};
  if (std::find(backgrounds.begin(), backgrounds.end(), background) == backgrounds.end())
    return Status::InvalidArgument("background.type must be flat, backdrop or room");
  for (const auto& e : effects)
    if (std::find(KnownEffects().begin(), KnownEffects().end(), e) == KnownEffects().end())
      return Status::InvalidArgument("unknown effect '" + e + "'");
  for (const Curve* c : {&yaw, &pitch, &roll, &tx, &ty, &tz})
    for (const auto& term : c->terms) HF_RETURN_IF_ERROR(CheckCurveTerm(term).WithContext("head"));
  for (const auto& [name, curve] : expressions)
    for (const auto& term : curve.terms) HF_RETURN_IF_ERROR(CheckCurveTerm(term).WithContext("expressions." + name));
  if (texture_size < 64 || texture_size > 8192) return Status::InvalidArgument("appearance.texture_size must be in [64, 8192]");
  return Status::Ok();
}

namespace {

// Reads typed values with errors that name the key.
class Reader {
 public:
  explicit Reader(std::string source) : source_(std::move(source)) {}
  Status status() const { return status_; }

  void Fail(const std::string& key, const std::string& what) {
    if (status_.ok()) status_ = Status::InvalidArgument(source_ + ": " + key + ": " + what);
  }

  void Number(const toml::table& t, const std::string& prefix, const char* key, double* out) {
    const toml::node* n = t.get(key);
    if (!n) return;
    if (auto v = n->value<double>()) *out = *v;
    else Fail(prefix + key, "expected a number");
  }
  void Integer(const toml::table& t, const std::string& prefix, const char* key, int* out) {
    const toml::node* n = t.get(key);
    if (!n) return;
    if (auto v = n->value<int64_t>()) *out = static_cast<int>(*v);
    else Fail(prefix + key, "expected an integer");
  }
  void Text(const toml::table& t, const std::string& prefix, const char* key, std::string* out) {
    const toml::node* n = t.get(key);
    if (!n) return;
    if (auto v = n->value<std::string>()) *out = *v;
    else Fail(prefix + key, "expected a string");
  }
  std::vector<double> Numbers(const toml::node& n, const std::string& key) {
    std::vector<double> out;
    const toml::array* a = n.as_array();
    if (!a) {
      Fail(key, "expected an array of numbers");
      return out;
    }
    for (const auto& e : *a) {
      if (auto v = e.value<double>()) out.push_back(*v);
      else Fail(key, "expected an array of numbers");
    }
    return out;
  }
  void NumberList(const toml::table& t, const std::string& prefix, const char* key, std::vector<double>* out) {
    if (const toml::node* n = t.get(key)) *out = Numbers(*n, prefix + key);
  }
  template <typename Vec>
  void Vector3(const toml::table& t, const std::string& prefix, const char* key, Vec* out) {
    const toml::node* n = t.get(key);
    if (!n) return;
    const auto v = Numbers(*n, prefix + key);
    if (v.size() != 3) return Fail(prefix + key, "expected 3 numbers");
    *out = Vec(static_cast<typename Vec::Scalar>(v[0]), static_cast<typename Vec::Scalar>(v[1]),
               static_cast<typename Vec::Scalar>(v[2]));
  }

  CurveTerm Term(const toml::table& t, const std::string& key, uint64_t default_seed) {
    CurveTerm c;
    c.seed = default_seed;
    Text(t, key + ".", "type", &c.type);
    Number(t, key + ".", "value", &c.value);
    Number(t, key + ".", "amplitude", &c.amplitude);
    Number(t, key + ".", "period", &c.period);
    Number(t, key + ".", "phase", &c.phase);
    Number(t, key + ".", "offset", &c.offset);
    Number(t, key + ".", "timescale", &c.timescale);
    Number(t, key + ".", "rate", &c.rate);
    Number(t, key + ".", "duration", &c.duration);
    NumberList(t, key + ".", "times", &c.times);
    NumberList(t, key + ".", "values", &c.values);
    int seed = static_cast<int>(default_seed);
    Integer(t, key + ".", "seed", &seed);
    c.seed = static_cast<uint64_t>(seed);
    return c;
  }

  // A curve is a number (constant), a table (one term) or an array of tables.
  Curve ReadCurve(const toml::node& n, const std::string& key, uint64_t default_seed) {
    Curve curve;
    if (auto v = n.value<double>()) {
      CurveTerm c;
      c.type = "constant";
      c.value = *v;
      curve.terms.push_back(c);
    } else if (const toml::table* t = n.as_table()) {
      curve.terms.push_back(Term(*t, key, default_seed));
    } else if (const toml::array* a = n.as_array()) {
      uint64_t seed = default_seed;
      for (const auto& e : *a) {
        if (const toml::table* t = e.as_table()) curve.terms.push_back(Term(*t, key, seed++));
        else Fail(key, "expected a table per curve term");
      }
    } else {
      Fail(key, "expected a number, a curve table or an array of them");
    }
    return curve;
  }

 private:
  std::string source_;
  Status status_;
};

uint64_t NameSeed(const std::string& name, int scene_seed) {
  uint64_t h = static_cast<uint64_t>(scene_seed) * 1000003ULL;
  for (char c : name) h = h * 131 + static_cast<unsigned char>(c);
  return h;
}

// The [camera] table.
void ReadCamera(const toml::table* t, Reader* reader, SceneCamera* camera) {
  Reader& r = *reader;
  SceneCamera& c = *camera;
  r.Text(*t, "camera.", "rig", &c.rig);
  r.Vector3(*t, "camera.", "position", &c.position);
  r.Vector3(*t, "camera.", "target", &c.target);
  r.Number(*t, "camera.", "radius", &c.radius);
  r.NumberList(*t, "camera.", "elevations", &c.elevations);
  r.Integer(*t, "camera.", "count", &c.count);
  r.Number(*t, "camera.", "arc", &c.arc_deg);
  r.Number(*t, "camera.", "elevation", &c.elevation_deg);
  r.Number(*t, "camera.", "shake", &c.shake_m);
  r.Number(*t, "camera.", "shake_deg", &c.shake_deg);
  r.Number(*t, "camera.", "shake_timescale", &c.shake_timescale);
  if (const toml::array* a = (*t)["positions"].as_array()) {
    for (const auto& e : *a) {
      const auto v = r.Numbers(e, "camera.positions");
      if (v.size() == 3) c.positions.emplace_back(v[0], v[1], v[2]);
      else r.Fail("camera.positions", "expected [x, y, z] per camera");
    }
  }
  if (const toml::table* in = (*t)["intrinsics"].as_table()) {
    auto& i = c.intrinsics;
    r.Integer(*in, "camera.intrinsics.", "width", &i.width);
    r.Integer(*in, "camera.intrinsics.", "height", &i.height);
    r.Number(*in, "camera.intrinsics.", "focal", &i.focal);
    r.Number(*in, "camera.intrinsics.", "fov_deg", &i.fov_deg);
    r.Number(*in, "camera.intrinsics.", "cx", &i.cx);
    r.Number(*in, "camera.intrinsics.", "cy", &i.cy);
    r.Number(*in, "camera.intrinsics.", "k1", &i.k1);
    r.Number(*in, "camera.intrinsics.", "k2", &i.k2);
  }
}

}  // namespace

Status ParseScene(const std::string& text, const std::string& source, Scene* scene) {
  toml::table root;
  try {
    root = toml::parse(text, source);
  } catch (const toml::parse_error& e) {
    return Status::InvalidArgument(source + ": " + std::string(e.description()) + " (line " +
                                   std::to_string(e.source().begin.line) + ")");
  }
  Scene s;
  Reader r(source);
  r.Text(root, "", "name", &s.name);
  r.Number(root, "", "duration", &s.duration);
  r.Number(root, "", "fps", &s.fps);
  r.Integer(root, "", "frames", &s.frames);
  r.Integer(root, "", "seed", &s.seed);
  if (const toml::table* t = root["render"].as_table()) r.Integer(*t, "render.", "supersample", &s.supersample);

  if (const toml::table* t = root["subject"].as_table()) {
    if (const toml::node* id = t->get("identity")) {
      if (auto text_value = id->value<std::string>()) {
        if (*text_value != "random") r.Fail("subject.identity", "expected \"random\" or an array of numbers");
        s.random_identity = true;
      } else {
        s.identity = r.Numbers(*id, "subject.identity");
        s.random_identity = false;
      }
    }
    r.Integer(*t, "subject.", "identity_seed", &s.identity_seed);
    r.Integer(*t, "subject.", "identity_modes", &s.identity_modes);
    r.Number(*t, "subject.", "identity_scale", &s.identity_scale);
  }
  if (const toml::table* t = root["appearance"].as_table()) {
    r.Vector3(*t, "appearance.", "skin", &s.skin);
    r.Vector3(*t, "appearance.", "hair", &s.hair);
    r.Vector3(*t, "appearance.", "iris", &s.iris);
    r.Vector3(*t, "appearance.", "teeth", &s.teeth);
    r.Number(*t, "appearance.", "freckles", &s.freckles);
    r.Number(*t, "appearance.", "pores", &s.pores);
    r.Integer(*t, "appearance.", "seed", &s.appearance_seed);
    r.Integer(*t, "appearance.", "texture_size", &s.texture_size);
  }
  if (const toml::table* t = root["background"].as_table()) {
    r.Text(*t, "background.", "type", &s.background);
    r.Vector3(*t, "background.", "colour", &s.background_colour);
    r.Number(*t, "background.", "distance", &s.backdrop_distance);
    r.Number(*t, "background.", "room_size", &s.room_size);
    r.Integer(*t, "background.", "seed", &s.background_seed);
  }
  if (const toml::table* t = root["camera"].as_table()) ReadCamera(t, &r, &s.camera);
  if (const toml::table* t = root["head"].as_table()) {
    const std::pair<const char*, Curve*> curves[] = {{"yaw", &s.yaw}, {"pitch", &s.pitch}, {"roll", &s.roll},
                                                     {"x", &s.tx},    {"y", &s.ty},         {"z", &s.tz}};
    for (const auto& [key, curve] : curves)
      if (const toml::node* n = t->get(key)) *curve = r.ReadCurve(*n, std::string("head.") + key, NameSeed(key, s.seed));
  }
  if (const toml::table* t = root["expressions"].as_table()) {
    for (const auto& [key, node] : *t) {
      const std::string name(key.str());
      // Left/right pairs share a seed so that blinks stay synchronous.
      std::string base = name;
      if (base.size() > 2 && (base.substr(base.size() - 2) == "_L" || base.substr(base.size() - 2) == "_R"))
        base = base.substr(0, base.size() - 2);
      s.expressions[name] = r.ReadCurve(node, "expressions." + name, NameSeed(base, s.seed));
    }
  }
  if (const toml::node* n = root.get("effects")) {
    if (const toml::array* a = n->as_array()) {
      for (const auto& e : *a) {
        if (auto v = e.value<std::string>()) s.effects.push_back(*v);
        else r.Fail("effects", "expected an array of effect names");
      }
    } else {
      r.Fail("effects", "expected an array of effect names");
    }
  }
  if (const toml::table* t = root["effect"].as_table()) {
    for (const auto& [name, node] : *t) {
      const toml::table* params = node.as_table();
      if (!params) {
        r.Fail("effect." + std::string(name.str()), "expected a table of parameters");
        continue;
      }
      for (const auto& [key, value] : *params) {
        if (auto v = value.value<double>()) s.effect_params[std::string(name.str())][std::string(key.str())] = *v;
        else r.Fail("effect." + std::string(name.str()) + "." + std::string(key.str()), "expected a number");
      }
    }
  }
  HF_RETURN_IF_ERROR(r.status());
  HF_RETURN_IF_ERROR(s.Check().WithContext(source));
  *scene = std::move(s);
  return Status::Ok();
}

Status LoadScene(const std::string& path, Scene* scene) {
  std::string text;
  HF_RETURN_IF_ERROR(ReadFileToString(path, &text).WithContext("scene"));
  return ParseScene(text, path, scene);
}

}  // namespace headforge
