// The batch manifest's checks, a dry run's jobs and a job's arguments: no
// cluster needed (tests/slurm_test.cc runs a batch on a real one).
#include <gtest/gtest.h>
#include <signal.h>

#include <chrono>
#include <sstream>
#include <thread>

#include "core/json_io.h"
#include "core/process.h"
#include "pipelines/batch_slurm.h"

namespace headforge {
namespace {

const std::vector<std::string> kPresets = {"draft", "standard", "high"};
// Names a shell would split or run; each must stay one argument.
const std::string kOdd = "it's \"odd\"; $(touch pwned) `id` a  b";

fs::path Scratch(const std::string& name) {
  const fs::path dir = fs::temp_directory_path() / ("hf_batch_test_" + name);
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

void Touch(const fs::path& path) { ASSERT_TRUE(WriteFileAtomic(path, "x").ok()); }

std::string Slurp(const fs::path& path) {
  std::string text;
  EXPECT_TRUE(ReadFileToString(path, &text).ok()) << path;
  return text;
}

std::vector<std::string> Lines(const std::string& text) {
  std::vector<std::string> lines;
  std::istringstream in(text);
  for (std::string line; std::getline(in, line);) lines.push_back(line);
  return lines;
}

TEST(BatchManifest, ReadsRowsWithRelativePathsCommentsAndOddNames) {
  const fs::path dir = Scratch("rows");
  Touch(dir / "a.mp4");
  Touch(dir / "b cam0.mp4");
  Touch(dir / "b cam1.mp4");
  Touch(dir / "tiny.ini");
  fs::create_directories(dir / "frames");
  const std::string text = "# name\tpreset\tconfig\tinputs\n\nalice\tdraft\t-\ta.mp4\n" + kOdd +
                           "\t\ttiny.ini\tb cam0.mp4\t" + (dir / "b cam1.mp4").string() + "\n" + "carol\thigh\t\tframes\t\n";
  std::vector<BatchRow> rows;
  const Status s = ParseManifest(text, dir, "m.tsv", kPresets, &rows);
  ASSERT_TRUE(s.ok()) << s.message();
  ASSERT_EQ(rows.size(), 3u);
  EXPECT_EQ(rows[0].name, "alice");
  EXPECT_EQ(rows[0].line, 3);
  EXPECT_EQ(rows[0].preset, "draft");
  EXPECT_EQ(rows[0].config, "");
  EXPECT_EQ(rows[0].inputs, std::vector<std::string>{(dir / "a.mp4").string()});
  EXPECT_EQ(rows[1].name, kOdd);
  EXPECT_EQ(rows[1].preset, "");
  EXPECT_EQ(rows[1].config, (dir / "tiny.ini").string());
  EXPECT_EQ(rows[1].inputs, (std::vector<std::string>{(dir / "b cam0.mp4").string(), (dir / "b cam1.mp4").string()}));
  EXPECT_EQ(rows[2].inputs, std::vector<std::string>{(dir / "frames").string()});
}

TEST(BatchManifest, RefusesEveryBadRowByLineAndName) {
  const fs::path dir = Scratch("bad");
  Touch(dir / "a.mp4");
  const std::string text =
      "good\tdraft\t-\ta.mp4\n"
      "missing\tdraft\t-\tnot_there.mp4\n"
      "good\tdraft\t-\ta.mp4\n"
      "fancy\tultra\t-\ta.mp4\n"
      "sub/dir\tdraft\t-\ta.mp4\n"
      ".hidden\tdraft\t-\ta.mp4\n"
      "-flag\tdraft\t-\ta.mp4\n"
      "short\tdraft\n"
      "noconfig\tdraft\tnone.ini\ta.mp4\n";
  std::vector<BatchRow> rows;
  const Status s = ParseManifest(text, dir, "m.tsv", kPresets, &rows);
  ASSERT_EQ(s.code(), Status::Code::kInvalidArgument);
  EXPECT_TRUE(rows.empty());
  const std::string& m = s.message();
  EXPECT_NE(m.find("nothing submitted"), std::string::npos) << m;
  EXPECT_NE(m.find("m.tsv line 2 (missing): input not found: " + (dir / "not_there.mp4").string()), std::string::npos)
      << m;
  EXPECT_NE(m.find("line 3 (good): duplicate name"), std::string::npos) << m;
  EXPECT_NE(m.find("line 4 (fancy): unknown preset 'ultra'"), std::string::npos) << m;
  EXPECT_NE(m.find("line 5 (sub/dir): bad name"), std::string::npos) << m;
  EXPECT_NE(m.find("line 6 (.hidden): bad name"), std::string::npos) << m;
  EXPECT_NE(m.find("line 7 (-flag): bad name"), std::string::npos) << m;
  EXPECT_NE(m.find("line 8 (short): needs name, preset, config"), std::string::npos) << m;
  EXPECT_NE(m.find("line 9 (noconfig): config not found"), std::string::npos) << m;
  EXPECT_EQ(m.find("line 1 "), std::string::npos) << m;
  EXPECT_FALSE(ParseManifest("# only a comment\n", dir, "m.tsv", kPresets, &rows).ok());
}

BatchPlan OddPlan(const fs::path& dir) {
  Touch(dir / "in put.mp4");
  BatchPlan plan;
  plan.id = "20261128-000000-00";
  plan.root = dir / "root $(x) 'q'";
  plan.headforge = "/opt/head forge/headforge";
  plan.stages = {"ingest", "calibrate", "train"};
  plan.rows = {{2, kOdd, "draft", "", {(dir / "in put.mp4").string()}}, {3, "plain", "", "", {(dir / "in put.mp4").string()}}};
  plan.slurm.partition = "cpu,train=gpu";
  plan.slurm.time = "30,train=2:00:00";
  plan.slurm.gres = "gpu:1";
  plan.slurm.max_parallel = 4;
  return plan;
}

TEST(BatchSlurm, DryRunShowsEachJobsArgumentsOneByOneAndWritesNothing) {
  const fs::path dir = Scratch("dry");
  BatchPlan plan = OddPlan(dir);
  ASSERT_TRUE(plan.slurm.Check(plan.stages).ok());
  std::ostringstream out;
  ASSERT_TRUE(SubmitBatch(&plan, /*dry_run=*/true, out).ok());
  EXPECT_FALSE(fs::exists(plan.root));
  EXPECT_TRUE(plan.job_ids.empty());
  std::vector<nlohmann::json> jobs;
  std::vector<std::string> submits;
  for (const auto& line : Lines(out.str())) {
    if (line.rfind("  [", 0) == 0) jobs.push_back(nlohmann::json::parse(line.substr(line.find(']') + 2)));
    if (line.rfind("submit: ", 0) == 0) submits.push_back(line);
  }
  ASSERT_EQ(jobs.size(), 6u) << out.str();  // 3 stages x 2 captures
  const std::vector<std::string> first = jobs[0].get<std::vector<std::string>>();
  const std::vector<std::string> expected = {"run", "--until", "ingest", "--workspace", (plan.root / kOdd).string(),
                                             "--video", (dir / "in put.mp4").string(), "--preset", "draft"};
  EXPECT_EQ(first, expected);
  EXPECT_EQ(jobs[5].get<std::vector<std::string>>()[2], "train");
  ASSERT_EQ(submits.size(), 3u);
  EXPECT_EQ(submits[0].find("--dependency"), std::string::npos) << submits[0];
  EXPECT_NE(submits[1].find("--dependency=aftercorr:"), std::string::npos) << submits[1];
  EXPECT_NE(submits[1].find("--kill-on-invalid-dep=yes"), std::string::npos) << submits[1];
  EXPECT_NE(submits[0].find("--partition=cpu --time=30"), std::string::npos) << submits[0];
  EXPECT_NE(submits[2].find("--partition=gpu --time=2:00:00 --gres=gpu:1"), std::string::npos) << submits[2];
  EXPECT_EQ(submits[1].find("--gres"), std::string::npos) << submits[1];
  EXPECT_NE(submits[0].find("--array=0-1%4"), std::string::npos) << submits[0];
  EXPECT_NE(submits[0].find("--signal=B:TERM@120"), std::string::npos) << submits[0];
  EXPECT_NE(submits[0].find("--requeue"), std::string::npos) << submits[0];
  SlurmOptions typo;
  typo.partition = "cpu,tarin=gpu";
  EXPECT_FALSE(typo.Check(plan.stages).ok());
}

// A program that writes its arguments, one a line, to $HF_ARGS_OUT, then
// exits with $HF_EXIT, or becomes `sleep $HF_SLEEP` when that is set.
fs::path ArgsRecorder(const fs::path& dir) {
  const fs::path script = dir / "record args";
  EXPECT_TRUE(WriteFileAtomic(script, "#!/bin/sh\nfor a in \"$@\"; do printf '%s\\n' \"$a\"; done > \"$HF_ARGS_OUT\"\n"
                                      "if [ -n \"$HF_SLEEP\" ]; then exec sleep \"$HF_SLEEP\"; fi\nexit \"${HF_EXIT:-0}\"\n")
                  .ok());
  fs::permissions(script, fs::perms::owner_all);
  return script;
}

TEST(BatchSlurm, JobScriptHandsTheBatchFolderOverAsOneArgument) {
  const fs::path dir = Scratch("script");
  BatchPlan plan = OddPlan(dir);
  plan.headforge = ArgsRecorder(dir).string();
  const fs::path script = dir / "ingest.sh";
  ASSERT_TRUE(WriteFileAtomic(script, plan.Script("ingest")).ok());
  ::setenv("HF_ARGS_OUT", (dir / "args.txt").c_str(), 1);
  int code = -1;
  ASSERT_TRUE(RunProgram({"sh", script.string()}, dir / "script.log", &code).ok());
  EXPECT_EQ(code, 0) << Slurp(dir / "script.log");
  EXPECT_EQ(Lines(Slurp(dir / "args.txt")), (std::vector<std::string>{"batch", "job", plan.Dir().string(), "ingest"}));
  EXPECT_FALSE(fs::exists(dir / "pwned"));
}

TEST(BatchSlurm, JobRunsItsCaptureAndSaysWhereTheLogIsOnFailureOrExits75OnSigterm) {
  const fs::path dir = Scratch("job");
  BatchPlan plan = OddPlan(dir);
  plan.headforge = ArgsRecorder(dir).string();
  ::setenv("HF_ARGS_OUT", (dir / "args.txt").c_str(), 1);
  ::unsetenv("SLURM_ARRAY_JOB_ID");
  ::setenv("HF_EXIT", "0", 1);
  EXPECT_EQ(RunBatchJob(plan, "calibrate", 0), 0);
  EXPECT_EQ(Lines(Slurp(dir / "args.txt")), plan.StageArgs("calibrate", 0));
  EXPECT_FALSE(fs::exists(dir / "pwned"));
  ::setenv("HF_EXIT", "3", 1);
  EXPECT_EQ(RunBatchJob(plan, "calibrate", 1), 3);
  // SIGTERM to the job goes on to its stage; the job says it was interrupted.
  ::setenv("HF_EXIT", "0", 1);
  ::setenv("HF_SLEEP", "30", 1);
  const auto start = std::chrono::steady_clock::now();
  std::thread signal([] {
    std::this_thread::sleep_for(std::chrono::milliseconds(700));
    ::kill(::getpid(), SIGTERM);
  });
  EXPECT_EQ(RunBatchJob(plan, "train", 0), kBatchExitInterrupted);
  signal.join();
  EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::seconds(20));
  ::unsetenv("HF_SLEEP");
  ::unsetenv("HF_EXIT");
}

TEST(BatchSlurm, ShellQuoteLeavesPlainWordsAndQuotesTheRest) {
  EXPECT_EQ(ShellQuote("/a/b-c_d.e"), "/a/b-c_d.e");
  EXPECT_EQ(ShellQuote("a b"), "'a b'");
  EXPECT_EQ(ShellQuote("it's"), "'it'\\''s'");
  EXPECT_EQ(ShellQuote(""), "''");
}

}  // namespace
}  // namespace headforge
