// The command line end to end on a real GRID clip: exit codes, help, the
// workspace's skip and resume behaviour, a SIGKILL mid-stage, failures that
// leave earlier outputs intact.
#include <gtest/gtest.h>
#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <fstream>
#include <sstream>
#include <thread>

#include "core/fs.h"
#include "core/hash.h"
#include "core/json_io.h"
#include "tests/run_headforge.h"
#include "tests/shared_workspace.h"

namespace headforge {
namespace {

const fs::path kGrid = fs::path(HEADFORGE_TEST_SHARED_DATA) / "video" / "grid";

bool Contains(const std::string& text, const std::string& part) {
  return text.find(part) != std::string::npos;
}

// The hash of the stage's outputs: frames, masks, landmarks and capture report.
std::string OutputsHash(const fs::path& ws) {
  Hasher h;
  EXPECT_TRUE(h.AddTreeContents(ws / "frames").ok());
  EXPECT_TRUE(h.AddTreeContents(ws / "masks").ok());
  EXPECT_TRUE(h.AddFileContents(ws / "landmarks.json").ok());
  EXPECT_TRUE(h.AddFileContents(ws / "capture.json").ok());
  return h.Hex();
}

class CliTest : public ::testing::Test {
 protected:
  // One full run of the acceptance clip, shared by the tests that compare
  // with it (and with track_test, which runs the same).
  static void SetUpTestSuite() {
    reference_ = SharedRun("grid_bbaf2n", {(kGrid / "bbaf2n.mpg").string()});
    first_run_.code = fs::exists(reference_ / ".complete") ? 0 : 1;
  }
  static fs::path Scratch(const std::string& name) {
    const fs::path dir = fs::temp_directory_path() / ("hf_cli_" + name);
    fs::remove_all(dir);
    return dir;
  }
  static fs::path reference_;
  static Result first_run_;
};
fs::path CliTest::reference_;
Result CliTest::first_run_;

TEST_F(CliTest, GridClipIngestsAllFramesWithLandmarks) {
  ASSERT_EQ(first_run_.code, 0) << first_run_.err;
  nlohmann::json landmarks, capture;
  ASSERT_TRUE(ReadJson(reference_ / "landmarks.json", &landmarks).ok());
  ASSERT_TRUE(ReadJson(reference_ / "capture.json", &capture).ok());
  const auto& frames = landmarks["cameras"]["cam0"];
  ASSERT_EQ(frames.size(), 75u);
  int found = 0;
  for (const auto& f : frames) {
    if (!f["found"].get<bool>()) continue;
    ++found;
    EXPECT_EQ(f["points"].size(), 68u);
  }
  EXPECT_GE(found, 72) << "68 landmarks on at least 95% of 75 frames";
  EXPECT_EQ(capture["report"]["kept"], 75);
  EXPECT_EQ(CountFiles(reference_ / "frames" / "cam0"), 75u);
  EXPECT_EQ(CountFiles(reference_ / "masks" / "cam0"), 75u);
  // The effective options sit beside the outputs.
  EXPECT_TRUE(Contains(Slurp(reference_ / "ingest.ini"), "[ingest]"));
  EXPECT_TRUE(Contains(Slurp(reference_ / "ingest.ini"), "resolution = 512"));

  const Result status = Headforge({"status", reference_.string()});
  EXPECT_EQ(status.code, 0);
  EXPECT_TRUE(Contains(status.out, "ingest     done")) << status.out;
  // A fixed camera: auto mode chose head-pose cameras; align followed.
  EXPECT_TRUE(Contains(status.out, "calibrate  done")) << status.out;
  EXPECT_TRUE(Contains(status.out, "head-pose")) << status.out;
  EXPECT_TRUE(Contains(status.out, "align      done")) << status.out;
  EXPECT_TRUE(Contains(status.out, "track      done")) << status.out;
  EXPECT_TRUE(Contains(status.out, "train      pending")) << status.out;
  EXPECT_TRUE(fs::exists(reference_ / "cameras.json"));
  EXPECT_TRUE(fs::exists(reference_ / "alignment.json"));
  EXPECT_TRUE(fs::exists(reference_ / "tracking.json"));
  EXPECT_TRUE(fs::exists(reference_ / "overlay_cam0.mp4"));
}

TEST_F(CliTest, SecondRunSkipsTheStageUntilAnOptionChanges) {
  ASSERT_EQ(first_run_.code, 0);
  const fs::path ws = Scratch("skip");
  fs::copy(reference_, ws, fs::copy_options::recursive);
  nlohmann::json before;
  ASSERT_TRUE(ReadJson(ws / "workspace.json", &before).ok());
  const auto capture_time = fs::last_write_time(ws / "capture.json");

  const Result again =
      Headforge({"run", "--video", (kGrid / "bbaf2n.mpg").string(), "--workspace", ws.string(), "--until", "track"});
  ASSERT_EQ(again.code, 0) << again.err;
  EXPECT_TRUE(Contains(again.err, "ingest: up to date")) << again.err;
  nlohmann::json after;
  ASSERT_TRUE(ReadJson(ws / "workspace.json", &after).ok());
  EXPECT_EQ(after["stages"][0]["finished_at"], before["stages"][0]["finished_at"]);
  EXPECT_EQ(fs::last_write_time(ws / "capture.json"), capture_time);

  // A changed option redoes the stage.
  const Result changed = Headforge({"run", "--video", (kGrid / "bbaf2n.mpg").string(), "--workspace",
                              ws.string(), "--until", "track", "--max-frames", "5", "--frame-size", "128"});
  ASSERT_EQ(changed.code, 0) << changed.err;
  EXPECT_FALSE(Contains(changed.err, "up to date"));
  EXPECT_EQ(CountFiles(ws / "frames" / "cam0"), 5u);
  // The training preset sets ingest's frame budget (--select) in a run: the
  // default (draft) 300, standard 2000; a budget given stays.
  EXPECT_TRUE(Contains(Slurp(ws / "ingest.ini"), "select = 300\n"));
  const std::vector<std::string> five = {"run", "--video", (kGrid / "bbaf2n.mpg").string(), "--workspace", ws.string(),
                                         "--until", "ingest", "--max-frames", "5", "--frame-size", "128"};
  std::vector<std::string> standard = five;
  // Without --device cpu: a run that stops before train is not refused for
  // the GPU preset's device on a CPU build.
  standard.insert(standard.end(), {"--preset", "standard"});
  const Result budget = Headforge(standard);
  ASSERT_EQ(budget.code, 0) << budget.err;
  EXPECT_FALSE(Contains(budget.err, "ingest: up to date"));
  EXPECT_TRUE(Contains(Slurp(ws / "ingest.ini"), "select = 2000\n"));
  standard.insert(standard.end(), {"--select", "40"});
  ASSERT_EQ(Headforge(standard).code, 0);
  EXPECT_TRUE(Contains(Slurp(ws / "ingest.ini"), "select = 40\n"));

  // A stage run alone is skipped when up to date, and runs again with --force.
  const std::vector<std::string> ingest = {"ingest", "--video", (kGrid / "bbaf2n.mpg").string(), "--workspace",
                                           ws.string(), "--max-frames", "5", "--frame-size", "128", "--select", "40"};
  const Result skipped = Headforge(ingest);
  ASSERT_EQ(skipped.code, 0) << skipped.err;
  EXPECT_TRUE(Contains(skipped.err, "ingest: up to date")) << skipped.err;
  std::vector<std::string> forced = ingest;
  forced.push_back("--force");
  const auto written = fs::last_write_time(ws / "capture.json");
  const Result redone = Headforge(forced);
  ASSERT_EQ(redone.code, 0) << redone.err;
  EXPECT_FALSE(Contains(redone.err, "up to date")) << redone.err;
  EXPECT_GT(fs::last_write_time(ws / "capture.json"), written);
  EXPECT_EQ(CountFiles(ws / "frames" / "cam0"), 5u);

  // Ingest ran again after the stages that read it: they are out of date and
  // say so; what reads them refuses, naming the stage to run; a run redoes
  // them even where their own options are unchanged.
  const Result stale = Headforge({"status", ws.string()});
  ASSERT_EQ(stale.code, 0);
  for (const char* line : {"calibrate  out of date", "align      out of date", "track      out of date",
                           "(ingest was run again after it)"})
    EXPECT_TRUE(Contains(stale.out, line)) << line << "\n" << stale.out;
  const std::string why = "needs calibrate run again first: its outputs are out of date (ingest was run again after it)";
  const Result track = Headforge({"track", "--workspace", ws.string()});
  EXPECT_EQ(track.code, 2);
  EXPECT_TRUE(Contains(track.err, "headforge: track " + why)) << track.err;
  const Result render = Headforge({"render", "--workspace", ws.string()});
  EXPECT_EQ(render.code, 2);
  EXPECT_TRUE(Contains(render.err, "headforge: render " + why)) << render.err;
  const Result pack = Headforge({"pack", "--workspace", ws.string(), "--out", (ws / "x.pack").string()});
  EXPECT_EQ(pack.code, 2);
  EXPECT_TRUE(Contains(pack.err, "headforge: pack " + why)) << pack.err;
  EXPECT_FALSE(fs::exists(ws / "x.pack"));
  // Without --video, ingest's inputs and options are those it last ran with:
  // up to date.
  const Result redone_all = Headforge({"run", "--workspace", ws.string(), "--until", "track"});
  ASSERT_EQ(redone_all.code, 0) << redone_all.err;
  EXPECT_TRUE(Contains(redone_all.err, "run: no --video: ingest's inputs and options as it last ran")) << redone_all.err;
  EXPECT_TRUE(Contains(redone_all.err, "ingest: up to date")) << redone_all.err;
  EXPECT_TRUE(Contains(redone_all.err, "calibrate: out of date (ingest was run again after it), redoing it"))
      << redone_all.err;
  EXPECT_FALSE(Contains(Headforge({"status", ws.string()}).out, "out of date"));
  // A preset given there sets the frame budget afresh (the recorded one was
  // the earlier preset's or --select's).
  const Result preset = Headforge({"run", "--workspace", ws.string(), "--until", "ingest", "--preset", "standard"});
  ASSERT_EQ(preset.code, 0) << preset.err;
  EXPECT_TRUE(Contains(Slurp(ws / "ingest.ini"), "select = 2000\n"));
  // A relative input recorded by a run in another folder is refused, not
  // read from this one.
  std::string ini = Slurp(ws / "ingest.ini");
  const std::string video = "video = " + (kGrid / "bbaf2n.mpg").string();
  ASSERT_TRUE(Contains(ini, video)) << ini;
  ini.replace(ini.find(video), video.size(), "video = elsewhere/bbaf2n.mpg");
  ASSERT_TRUE(WriteFileAtomic(ws / "ingest.ini", ini).ok());
  const Result relative = Headforge({"run", "--workspace", ws.string(), "--until", "track"});
  EXPECT_EQ(relative.code, 2);
  EXPECT_TRUE(Contains(relative.err, "gives --video elsewhere/bbaf2n.mpg, relative to the folder ingest ran in"))
      << relative.err;

  // A stage other than ingest does not make a workspace on a mistyped path.
  const Result nowhere = Headforge({"track", "--workspace", (ws / "nope").string()});
  EXPECT_EQ(nowhere.code, 1);
  EXPECT_TRUE(Contains(nowhere.err, "no workspace at " + (ws / "nope").string())) << nowhere.err;
  EXPECT_FALSE(fs::exists(ws / "nope"));
}

TEST_F(CliTest, KilledMidIngestResumesToTheSameOutputs) {
  ASSERT_EQ(first_run_.code, 0);
  const fs::path ws = Scratch("killed");
  const fs::path log = fs::temp_directory_path() / "hf_cli_killed.log";
  const pid_t pid = Spawn({"run", "--video", (kGrid / "bbaf2n.mpg").string(), "--workspace",
                           ws.string(), "--until", "track", "--threads", "1"},
                          log, log);
  // Wait until ingest is writing frames, then kill it without warning.
  const fs::path staging = ws / ".staging" / "ingest" / "frames" / "cam0";
  int status = 0;
  const bool killed = SignalWhen(pid, SIGKILL, [&] { return CountFiles(staging) >= 3; }, std::chrono::seconds(120),
                                 &status, std::chrono::milliseconds(5));
  ASSERT_TRUE(killed) << "ingest finished before it could be interrupted";
  ASSERT_TRUE(WIFSIGNALED(status));
  EXPECT_FALSE(fs::exists(ws / "capture.json"));  // nothing half-done reached the workspace

  const Result status_out = Headforge({"status", ws.string()});
  EXPECT_TRUE(Contains(status_out.out, "interrupted")) << status_out.out;

  // Resumed as far as ingest, whose outputs are compared (the later stages
  // after a kill: kill_test).
  const Result resumed =
      Headforge({"run", "--video", (kGrid / "bbaf2n.mpg").string(), "--workspace", ws.string(), "--until", "ingest"});
  ASSERT_EQ(resumed.code, 0) << resumed.err;
  EXPECT_TRUE(Contains(resumed.err, "interrupted")) << resumed.err;
  EXPECT_EQ(OutputsHash(ws), OutputsHash(reference_));
  EXPECT_FALSE(fs::exists(ws / ".staging" / "ingest"));
}

TEST_F(CliTest, FailedRerunKeepsEarlierOutputs) {
  ASSERT_EQ(first_run_.code, 0);
  const fs::path ws = Scratch("failed");
  fs::copy(reference_, ws, fs::copy_options::recursive);
  const std::string before = OutputsHash(ws);
  const fs::path corrupt = fs::temp_directory_path() / "hf_cli_corrupt.mp4";
  ASSERT_TRUE(WriteFileAtomic(corrupt, std::string(5000, 'x')).ok());
  const Result failed = Headforge({"run", "--video", corrupt.string(), "--workspace", ws.string(), "--until", "track"});
  EXPECT_EQ(failed.code, 1);
  EXPECT_TRUE(Contains(failed.err, "headforge: ingest: cannot decode")) << failed.err;
  EXPECT_TRUE(Contains(failed.err, "hf_cli_corrupt.mp4")) << failed.err;
  EXPECT_EQ(OutputsHash(ws), before);
  const Result status = Headforge({"status", ws.string()});
  EXPECT_TRUE(Contains(status.out, "ingest     failed")) << status.out;
}

TEST_F(CliTest, ConfigFileSetsDottedKeysAndCommandLineWins) {
  const fs::path ws = Scratch("config");
  const fs::path ini = fs::temp_directory_path() / "hf_cli_config.ini";
  ASSERT_TRUE(WriteFileAtomic(ini, "threads = 2\n[ingest]\nmax_frames = 4\nresolution = 96\nfps = 5\n").ok());
  // The frame size's old flag name still works, with a note naming the new one.
  const Result r = Headforge({"ingest", "--config", ini.string(), "--resolution", "64", "--video",
                        (kGrid / "lbax4n.mpg").string(), "--workspace", ws.string()});
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_TRUE(Contains(r.err, "--resolution is the old name of --frame-size")) << r.err;
  const std::string written = Slurp(ws / "ingest.ini");
  EXPECT_TRUE(Contains(written, "max_frames = 4")) << written;
  EXPECT_TRUE(Contains(written, "resolution = 64")) << written;
  EXPECT_TRUE(Contains(written, "fps = 5")) << written;
  EXPECT_EQ(CountFiles(ws / "frames" / "cam0"), 4u);
}

TEST(Cli, HelpVersionAndUsageErrors) {
  const Result help = Headforge({"--help"});
  EXPECT_EQ(help.code, 0);
  for (const char* command : {"run", "ingest", "calibrate", "align", "track", "simulate", "splat-fit", "face-model",
                              "bench", "status", "version"})
    EXPECT_TRUE(Contains(help.out, command));
  const Result track_help = Headforge({"track", "--help"});
  EXPECT_EQ(track_help.code, 0);
  for (const char* text : {"--identity-modes, --track.identity_modes", "default: 20", "--overlay"})
    EXPECT_TRUE(Contains(track_help.out, text)) << text;

  const Result ingest_help = Headforge({"ingest", "--help"});
  EXPECT_EQ(ingest_help.code, 0);
  for (const char* text : {"--fps, --ingest.fps", "--max-frames", "--start", "--end", "--mask-folder",
                           "--frame-size, --ingest.resolution <int> (formerly --resolution)", "default: 512", "--detector", "--workspace", "--threads"})
    EXPECT_TRUE(Contains(ingest_help.out, text)) << text;

  const Result version = Headforge({"--version"});
  EXPECT_EQ(version.code, 0);
  EXPECT_TRUE(Contains(version.out, "headforge 0.1.0"));
  EXPECT_TRUE(Contains(version.out, "COLMAP 3.8"));

  EXPECT_EQ(Headforge({"frobnicate"}).code, 2);
  const Result unknown = Headforge({"ingest", "--no-such-flag"});
  EXPECT_EQ(unknown.code, 2);
  EXPECT_TRUE(Contains(unknown.err, "no-such-flag"));
  const Result bad = Headforge({"run", "--video", (kGrid / "bbaf2n.mpg").string(), "--workspace",
                          "/tmp/hf_cli_bad", "--frame-size", "0"});
  EXPECT_EQ(bad.code, 2);
  EXPECT_TRUE(Contains(bad.err, "--frame-size must be a positive")) << bad.err;
  const Result missing = Headforge({"run", "--video", "/no/such.mp4", "--workspace", "/tmp/hf_cli_missing"});
  EXPECT_EQ(missing.code, 1);
  EXPECT_TRUE(Contains(missing.err, "/no/such.mp4")) << missing.err;
  const Result no_ws = Headforge({"status", "/tmp/hf_cli_never_created"});
  EXPECT_EQ(no_ws.code, 1);
  const Result no_ws_flag = Headforge({"status", "--workspace", "/tmp/hf_cli_never_created"});  // as elsewhere
  EXPECT_EQ(no_ws_flag.code, 1);
  EXPECT_TRUE(Contains(no_ws_flag.err, "no workspace at /tmp/hf_cli_never_created")) << no_ws_flag.err;
  // An option no model takes is said as it is, without --model auto's words.
  const Result steps = Headforge({"train", "--workspace", "/tmp/hf_cli_never_created", "--steps", "-5"});
  EXPECT_EQ(steps.code, 2);
  EXPECT_TRUE(Contains(steps.err, "headforge: train: --steps must be at least 1")) << steps.err;
  EXPECT_FALSE(fs::exists("/tmp/hf_cli_never_created"));
  const Result bench_help = Headforge({"bench", "calibrate", "--help"});
  EXPECT_EQ(bench_help.code, 0);
  for (const char* text : {"--repeat", "--quick", "--scenes"}) EXPECT_TRUE(Contains(bench_help.out, text)) << text;
  const Result no_repeat = Headforge({"bench", "calibrate", "--repeat", "0", "--out", "/tmp/hf_cli_bench"});
  EXPECT_EQ(no_repeat.code, 2);
  EXPECT_TRUE(Contains(no_repeat.err, "--repeat must be at least 1")) << no_repeat.err;
  EXPECT_FALSE(fs::exists("/tmp/hf_cli_bench"));  // refused before anything was simulated
  const Result track_bench_help = Headforge({"bench", "track", "--help"});
  EXPECT_EQ(track_bench_help.code, 0);
  for (const char* text : {"--seeds", "--json", "identity columns"})
    EXPECT_TRUE(Contains(track_bench_help.out, text)) << text;
  const Result both = Headforge({"embed-landmarks", "--views", "--identity", "--out", "/tmp/hf_cli_embedding.json"});
  EXPECT_EQ(both.code, 2);
  EXPECT_TRUE(Contains(both.err, "give one")) << both.err;
  EXPECT_FALSE(fs::exists("/tmp/hf_cli_embedding.json"));
}

// face-model inspect on the shipped model: its summary and one table row per
// rigid motion; an unknown point set is a clear error.
TEST(Cli, FaceModelInspectPrintsTheModelAndTheImitationTable) {
  const Result r = Headforge({"face-model", "inspect", "--points", "landmarks"});
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_TRUE(Contains(r.out, "26719 vertices")) << r.out;
  EXPECT_TRUE(Contains(r.out, "53 expressions")) << r.out;
  for (const char* motion : {"pitch (x)", "yaw (y)", "roll (z)", "along x", "along y", "along z", "scale"})
    EXPECT_TRUE(Contains(r.out, motion)) << motion;
  const Result bad = Headforge({"face-model", "inspect", "--points", "elbows"});
  EXPECT_EQ(bad.code, 2);
  EXPECT_TRUE(Contains(bad.err, "unknown point set 'elbows'")) << bad.err;
}

}  // namespace
}  // namespace headforge

namespace headforge {
namespace {

// The simulator's output goes into ingest unchanged, and the landmarks ingest
// detects on it agree with the simulator's ground truth.
TEST(SimulateThenIngest, IngestAcceptsTheSimulatorsOutputUnchanged) {
  const fs::path root = fs::temp_directory_path() / "hf_cli_sim";
  fs::remove_all(root);
  const fs::path scenes = fs::path(HEADFORGE_TEST_SOURCE_DIR) / "scenes";
  const Result sim = Headforge({"simulate", "--scene", (scenes / "talking_static.toml").string(), "--out",
                                (root / "capture").string(), "--frames", "6"});
  ASSERT_EQ(sim.code, 0) << sim.err;
  const Result ingest = Headforge({"ingest", "--video", (root / "capture" / "cam0").string(), "--workspace",
                                   (root / "ws").string(), "--frame-size", "256"});
  ASSERT_EQ(ingest.code, 0) << ingest.err;

  nlohmann::json truth, landmarks, capture;
  ASSERT_TRUE(ReadJson(root / "capture" / "ground_truth.json", &truth).ok());
  ASSERT_TRUE(ReadJson(root / "ws" / "landmarks.json", &landmarks).ok());
  ASSERT_TRUE(ReadJson(root / "ws" / "capture.json", &capture).ok());
  ASSERT_EQ(capture["report"]["kept"], 6);
  const auto& crop = capture["cameras"][0]["crop"];
  const double x0 = crop["x0"], y0 = crop["y0"], scale = crop["scale"];
  std::vector<double> errors;
  for (int f = 0; f < 6; ++f) {
    const auto& detected = landmarks["cameras"]["cam0"][f];
    ASSERT_TRUE(detected["found"].get<bool>()) << "frame " << f;
    const int source = capture["cameras"][0]["frames"][f]["source_frame"];
    const auto& gt = truth["frames"][source]["views"]["cam0"]["landmarks"];
    for (int i = 17; i < 68; ++i) {  // the jaw contour is defined differently by detector and model
      const double gx = (gt[i][0].get<double>() + 0.5 - x0) * scale - 0.5;
      const double gy = (gt[i][1].get<double>() + 0.5 - y0) * scale - 0.5;
      errors.push_back(std::hypot(detected["points"][i][0].get<double>() - gx,
                                  detected["points"][i][1].get<double>() - gy) / scale);
    }
  }
  std::nth_element(errors.begin(), errors.begin() + errors.size() / 2, errors.end());
  const double median = errors[errors.size() / 2];
  std::printf("median detected-vs-true landmark distance: %.2f px of the 512 px simulator frame\n", median);
  EXPECT_LT(median, 6.0);
}

// splat-fit end to end on a small orbit: the fit improves on held-out views,
// writes its loss curve, a report and a PLY with the reported count.
TEST(SplatFit, FitsHeldOutViewsAndWritesItsOutputs) {
  const fs::path out = fs::temp_directory_path() / "hf_cli_splat_fit";
  fs::remove_all(out);
  const fs::path scene = fs::path(HEADFORGE_TEST_SOURCE_DIR) / "scenes" / "orbit_360.toml";
  const Result fit = Headforge({"splat-fit", "--scene", scene.string(), "--out", out.string(), "--resolution", "48",
                                "--frames", "48", "--iterations", "500", "--eval-every", "100", "--init-points",
                                "3000", "--densify-until", "400", "--log-every", "50"});
  ASSERT_EQ(fit.code, 0) << fit.err;
  nlohmann::json report;
  ASSERT_TRUE(ReadJson(out / "report.json", &report).ok());
  EXPECT_EQ(report["test_views"], 6);
  EXPECT_EQ(report["train_views"], 42);
  EXPECT_EQ(report["steps"], 500);

  std::vector<nlohmann::json> evals, losses;
  std::ifstream stats(out / "stats.jsonl");
  for (std::string line; std::getline(stats, line);) {
    const auto j = nlohmann::json::parse(line);
    (j.contains("test_psnr") ? evals : losses).push_back(j);
  }
  ASSERT_EQ(losses.size(), 10u);
  ASSERT_EQ(evals.size(), 5u);  // steps 100..400, and the final one
  EXPECT_LT(losses.back()["loss"].get<double>(), 0.8 * losses.front()["loss"].get<double>());
  const double first = evals.front()["test_psnr"], last = report["test_psnr"];
  std::printf("splat-fit held-out PSNR: %.2f dB at step 100, %.2f dB at step 500\n", first, last);
  EXPECT_GT(last, first + 1.0);
  EXPECT_GT(last, 14.0);
  EXPECT_GT(report["test_ssim"].get<double>(), 0.3);

  // The PLY holds the reported number of Gaussians.
  std::ifstream ply(out / "gaussians.ply", std::ios::binary);
  int64_t vertices = -1;
  for (std::string line; std::getline(ply, line) && line != "end_header";) {
    if (line.rfind("element vertex ", 0) == 0) vertices = std::stoll(line.substr(15));
  }
  EXPECT_EQ(vertices, report["gaussians"].get<int64_t>());
  EXPECT_TRUE(fs::exists(out / "held_out" / "cam0_4.png"));
}

}  // namespace
}  // namespace headforge
