// Expensive fixtures made once and shared by every test, in any test binary,
// that asks for them with the same arguments: a simulated capture, or a
// workspace that `headforge run` took through track. Each lives in
// HEADFORGE_TEST_BINARY_DIR/test_workspaces/<name>-<key>, where the key
// hashes the arguments and the headforge binary's stamp (a rebuilt binary
// makes them afresh). A file lock serialises their making, so tests that
// ctest runs in parallel wait for the first. Tests that change a shared
// workspace work on a copy (CopyOf).
#pragma once

#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>

#include <algorithm>
#include <functional>
#include <map>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "core/fs.h"
#include "core/hash.h"
#include "core/json_io.h"
#include "tests/run_headforge.h"

namespace headforge {

// Makes `dir` with `make` unless an earlier call did; false (and `*error`
// saying why) when making failed.
inline bool MakeOnce(const fs::path& dir, const std::function<Result(const fs::path&)>& make, std::string* error) {
  fs::create_directories(dir.parent_path());
  const std::string lock_path = dir.string() + ".lock";
  const int fd = ::open(lock_path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
  if (fd < 0 || ::flock(fd, LOCK_EX) != 0) {
    *error = "cannot lock " + lock_path;
    return false;
  }
  bool ok = fs::exists(dir / ".complete");
  if (!ok) {
    fs::remove_all(dir);
    const Result made = make(dir);
    ok = made.code == 0;
    if (ok) {
      ok = WriteFileAtomic(dir / ".complete", "").ok();
    } else {
      *error = made.err;
    }
  }
  ::flock(fd, LOCK_UN);
  ::close(fd);
  return ok;
}

// The thread count a fixture is made with, named on its command line: the
// solvers' results depend on it in the last digits, so a fixture made by a
// test that runs headforge on one thread (HEADFORGE_THREADS=1) must equal
// the one a test running it on every thread would have made.
inline std::string FixtureThreads() { return std::to_string(std::max(1u, std::thread::hardware_concurrency())); }

inline fs::path SharedDir(const std::string& name, const std::vector<std::string>& args) {
  Hasher h;
  EXPECT_TRUE(h.AddFileStamp(HEADFORGE_BINARY).ok());
  for (const auto& a : args) h.Add(a);
  return fs::path(HEADFORGE_TEST_BINARY_DIR) / "test_workspaces" / (name + "-" + h.Hex());
}

// `headforge simulate` of scenes/<scene>.toml, its first `frames` frames.
inline fs::path SharedSimulation(const std::string& scene, int frames) {
  const std::vector<std::string> args = {
      "simulate", "--scene", (fs::path(HEADFORGE_TEST_SOURCE_DIR) / "scenes" / (scene + ".toml")).string(),
      "--frames", std::to_string(frames), "--threads", FixtureThreads()};
  const fs::path dir = SharedDir(scene + "_" + std::to_string(frames), args);
  std::string error;
  const bool ok = MakeOnce(dir, [&](const fs::path& out) {
    std::vector<std::string> full = args;
    full.insert(full.end(), {"--out", out.string()});
    return Headforge(full);
  }, &error);
  EXPECT_TRUE(ok) << error;
  return dir;
}

// The videos (or image folders) of a simulated capture, one per camera.
inline std::vector<std::string> SimulatedInputs(const fs::path& capture) {
  nlohmann::json truth;
  EXPECT_TRUE(ReadJson(capture / "ground_truth.json", &truth).ok());
  std::vector<std::string> inputs;
  for (const auto& cam : truth["cameras"]) inputs.push_back((capture / cam["input"].get<std::string>()).string());
  return inputs;
}

// `headforge run --until track --video INPUTS... OPTIONS... --workspace DIR`.
inline fs::path SharedRun(const std::string& name, const std::vector<std::string>& inputs,
                          const std::vector<std::string>& options = {}) {
  std::vector<std::string> args = {"run", "--until", "track", "--video"};
  args.insert(args.end(), inputs.begin(), inputs.end());
  args.insert(args.end(), options.begin(), options.end());
  args.insert(args.end(), {"--threads", FixtureThreads()});
  const fs::path dir = SharedDir(name, args);
  std::string error;
  const bool ok = MakeOnce(dir, [&](const fs::path& ws) {
    std::vector<std::string> full = args;
    full.insert(full.end(), {"--workspace", ws.string()});
    return Headforge(full);
  }, &error);
  EXPECT_TRUE(ok) << error;
  return dir;
}

// A private copy of a shared workspace at `to` (replacing what was there).
inline fs::path CopyOf(const fs::path& shared, const fs::path& to) {
  fs::remove_all(to);
  fs::copy(shared, to, fs::copy_options::recursive);
  fs::remove(to / ".complete");
  return to;
}

// The simulated talking_static capture (125 frames) taken through track: the
// workspace the training tests start from (a copy when they change it).
inline fs::path TrackedTalkingStatic() {
  return SharedRun("talking_static_125_run", SimulatedInputs(SharedSimulation("talking_static", 125)));
}

// A file's contents as a hash, to compare two runs' outputs.
inline std::string FileHash(const fs::path& path) {
  Hasher h;
  EXPECT_TRUE(h.AddFileContents(path).ok()) << path;
  return h.Hex();
}

// Every file of a workspace with its contents' hash (the run's own record,
// its lock and what a failure leaves in failed/ and .staging/ aside): what
// a failed run must leave as it was.
inline std::map<std::string, std::string> Snapshot(const fs::path& ws) {
  std::map<std::string, std::string> files;
  for (const auto& entry : fs::recursive_directory_iterator(ws)) {
    if (!entry.is_regular_file()) continue;
    const std::string rel = fs::relative(entry.path(), ws).string();
    if (rel == "workspace.json" || rel == ".lock" || rel.rfind("failed/", 0) == 0 || rel.rfind(".staging/", 0) == 0)
      continue;
    files[rel] = FileHash(entry.path());
  }
  return files;
}

// stats.jsonl's lines.
inline std::vector<nlohmann::json> StatsLines(const fs::path& path) {
  std::vector<nlohmann::json> lines;
  std::istringstream in(Slurp(path));
  for (std::string line; std::getline(in, line);) lines.push_back(nlohmann::json::parse(line));
  return lines;
}

}  // namespace headforge
