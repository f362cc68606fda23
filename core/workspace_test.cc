#include "core/workspace.h"

#include <gtest/gtest.h>

#include <map>

namespace headforge {
namespace {

class WorkspaceTest : public ::testing::Test {
 protected:
  void SetUp() override {
    root_ = fs::temp_directory_path() /
            ("hf_ws_" + std::string(::testing::UnitTest::GetInstance()->current_test_info()->name()));
    fs::remove_all(root_);
  }
  void TearDown() override { fs::remove_all(root_); }
  fs::path root_;
};

// Adapts a body that needs only the staging folder.
StageBody Body(std::function<Status(const fs::path&, StageResult*)> body) {
  return [body](const StageContext& context, StageResult* result) { return body(context.staging, result); };
}

Status WriteOutput(const fs::path& staging, StageResult* result, const std::string& text) {
  HF_RETURN_IF_ERROR(WriteFileAtomic(staging / "out" / "a.txt", text));
  result->outputs = {"out"};
  result->message = "wrote " + text;
  return Status::Ok();
}

TEST_F(WorkspaceTest, RunsOnceThenSkipsUntilFingerprintChanges) {
  std::unique_ptr<Workspace> ws;
  ASSERT_TRUE(Workspace::Open(root_, Workspace::Mode::kReadWrite, &ws).ok());
  int runs = 0;
  auto body = [&](const fs::path& staging, StageResult* result) {
    ++runs;
    return WriteOutput(staging, result, "v" + std::to_string(runs));
  };
  bool skipped = true;
  ASSERT_TRUE(RunStage(ws.get(), {"ingest", "f1", "[ingest]\n"}, Body(body), &skipped).ok());
  EXPECT_FALSE(skipped);
  ASSERT_TRUE(RunStage(ws.get(), {"ingest", "f1", "[ingest]\n"}, Body(body), &skipped).ok());
  EXPECT_TRUE(skipped);
  EXPECT_EQ(runs, 1);
  ASSERT_TRUE(RunStage(ws.get(), {"ingest", "f2", "[ingest]\n"}, Body(body), &skipped).ok());
  EXPECT_FALSE(skipped);
  EXPECT_EQ(runs, 2);
  const StageRecord* r = ws->Find("ingest");
  ASSERT_NE(r, nullptr);
  EXPECT_EQ(r->status, StageStatus::kDone);
  EXPECT_EQ(r->fingerprint, "f2");
  EXPECT_TRUE(fs::exists(root_ / "out" / "a.txt"));
  EXPECT_TRUE(fs::exists(root_ / "ingest.ini"));
  EXPECT_FALSE(fs::exists(root_ / ".staging" / "ingest"));
}

TEST_F(WorkspaceTest, MissingOutputForcesRerun) {
  std::unique_ptr<Workspace> ws;
  ASSERT_TRUE(Workspace::Open(root_, Workspace::Mode::kReadWrite, &ws).ok());
  int runs = 0;
  auto body = [&](const fs::path& staging, StageResult* result) {
    ++runs;
    return WriteOutput(staging, result, "x");
  };
  bool skipped;
  ASSERT_TRUE(RunStage(ws.get(), {"ingest", "f", ""}, Body(body), &skipped).ok());
  fs::remove_all(root_ / "out");
  ASSERT_TRUE(RunStage(ws.get(), {"ingest", "f", ""}, Body(body), &skipped).ok());
  EXPECT_FALSE(skipped);
  EXPECT_EQ(runs, 2);
}

TEST_F(WorkspaceTest, FailureKeepsEarlierOutputsAndIsRecorded) {
  std::unique_ptr<Workspace> ws;
  ASSERT_TRUE(Workspace::Open(root_, Workspace::Mode::kReadWrite, &ws).ok());
  bool skipped;
  ASSERT_TRUE(RunStage(ws.get(), {"ingest", "f1", ""}, Body([](const fs::path& s, StageResult* r) { return WriteOutput(s, r, "good"); }),
                       &skipped)
                  .ok());
  const Status status = RunStage(
      ws.get(), {"ingest", "f2", ""}, Body([](const fs::path& staging, StageResult* result) {
        WriteOutput(staging, result, "half").ok();
        return Status::DataError("no face found");
      }),
      &skipped);
  ASSERT_FALSE(status.ok());
  EXPECT_NE(status.message().find("no face found"), std::string::npos);
  std::string text;
  ASSERT_TRUE(ReadFileToString(root_ / "out" / "a.txt", &text).ok());
  EXPECT_EQ(text, "good");
  EXPECT_EQ(ws->Find("ingest")->status, StageStatus::kFailed);
}

TEST_F(WorkspaceTest, FailedAttemptsFilesAreKeptAndNamedInTheError) {
  std::unique_ptr<Workspace> ws;
  ASSERT_TRUE(Workspace::Open(root_, Workspace::Mode::kReadWrite, &ws).ok());
  bool skipped;
  const Status status = RunStage(
      ws.get(), {"calibrate", "f1", "x = 1\n"}, Body([](const fs::path& staging, StageResult*) {
        EXPECT_TRUE(WriteFileAtomic(staging / "colmap" / "colmap.log", "mapper: no good initial pair").ok());
        return Status::DataError("COLMAP failed; see " + (staging / "colmap" / "colmap.log").string());
      }),
      &skipped);
  ASSERT_FALSE(status.ok());
  EXPECT_EQ(status.code(), Status::Code::kDataError);
  const fs::path kept = root_ / "failed" / "calibrate" / "colmap" / "colmap.log";
  // The message points at the kept log, which is there to read.
  EXPECT_NE(status.message().find(kept.string()), std::string::npos) << status.message();
  EXPECT_EQ(status.message().find(".staging"), std::string::npos) << status.message();
  std::string text;
  ASSERT_TRUE(ReadFileToString(kept, &text).ok());
  EXPECT_EQ(text, "mapper: no good initial pair");
  EXPECT_NE(ws->Find("calibrate")->message.find(kept.string()), std::string::npos);

  // A failure that names no path gets the folder appended.
  const Status second = RunStage(
      ws.get(), {"calibrate", "f2", ""}, Body([](const fs::path& staging, StageResult*) {
        EXPECT_TRUE(WriteFileAtomic(staging / "partial.txt", "half").ok());
        return Status::DataError("no face found");
      }),
      &skipped);
  ASSERT_FALSE(second.ok());
  EXPECT_NE(second.message().find("kept in " + (root_ / "failed" / "calibrate").string()), std::string::npos)
      << second.message();
  EXPECT_TRUE(fs::exists(root_ / "failed" / "calibrate" / "partial.txt"));
  EXPECT_FALSE(fs::exists(kept));  // the older failure's files were replaced

  // A failure that wrote nothing keeps nothing and says nothing about it; a
  // success clears the last failure's folder.
  const Status third = RunStage(ws.get(), {"track", "f", ""}, Body([](const fs::path&, StageResult*) { return Status::DataError("no landmarks"); }),
                                &skipped);
  EXPECT_EQ(third.message(), "track: no landmarks");
  EXPECT_FALSE(fs::exists(root_ / "failed" / "track"));
  ASSERT_TRUE(RunStage(ws.get(), {"calibrate", "f3", ""}, Body([](const fs::path& s, StageResult* r) { return WriteOutput(s, r, "good"); }), &skipped)
                  .ok());
  EXPECT_FALSE(fs::exists(root_ / "failed" / "calibrate"));
}

TEST_F(WorkspaceTest, ManifestPersistsAndInterruptedRunIsDetected) {
  {
    std::unique_ptr<Workspace> ws;
    ASSERT_TRUE(Workspace::Open(root_, Workspace::Mode::kReadWrite, &ws).ok());
    fs::path staging;
    bool resumed = true;
    ASSERT_TRUE(ws->BeginStage("ingest", "f", {}, false, &staging, &resumed).ok());
    EXPECT_FALSE(resumed);
    // The process "dies" here: the lock is released with the object.
  }
  std::unique_ptr<Workspace> reader;
  ASSERT_TRUE(Workspace::Open(root_, Workspace::Mode::kReadOnly, &reader).ok());
  EXPECT_EQ(reader->Find("ingest")->status, StageStatus::kRunning);
  EXPECT_TRUE(reader->WasInterrupted("ingest"));
  EXPECT_FALSE(reader->IsUpToDate("ingest", "f"));
  const auto stages = reader->Stages({"ingest", "calibrate", "align", "track", "train", "export"});
  ASSERT_GE(stages.size(), 6u);
  EXPECT_EQ(stages[0].name, "ingest");
  EXPECT_EQ(stages[1].status, StageStatus::kPending);
}

// The record says running before the staging folder is made, so that a run
// killed between the two reads as interrupted; a staging folder that cannot
// be made fails the stage, with the reason.
TEST_F(WorkspaceTest, AStageIsRecordedRunningBeforeItsStagingFolderIsMade) {
  std::unique_ptr<Workspace> ws;
  ASSERT_TRUE(Workspace::Open(root_, Workspace::Mode::kReadWrite, &ws).ok());
  // The staging folders' place a link to nowhere: nothing is there to
  // remove, and no stage's folder can be made.
  fs::create_symlink(root_ / "nowhere" / "at all", Workspace::StagingPath(root_, "x").parent_path());
  fs::path staging;
  bool resumed = true;
  const Status begun = ws->BeginStage("ingest", "f", {}, false, &staging, &resumed);
  ASSERT_FALSE(begun.ok());
  ASSERT_NE(ws->Find("ingest"), nullptr);
  EXPECT_EQ(ws->Find("ingest")->status, StageStatus::kFailed);
  EXPECT_EQ(ws->Find("ingest")->message, begun.message());
  std::unique_ptr<Workspace> reader;
  ws.reset();
  ASSERT_TRUE(Workspace::Open(root_, Workspace::Mode::kReadOnly, &reader).ok());
  EXPECT_EQ(reader->Find("ingest")->status, StageStatus::kFailed);
  EXPECT_FALSE(reader->WasInterrupted("ingest"));
}

// A resumable stage whose run died is handed its staging folder back, with the
// checkpoint it wrote, when the fingerprint is unchanged; a changed
// fingerprint, or a stage that is not resumable, starts from an empty folder.
TEST_F(WorkspaceTest, ResumableStageGetsItsCheckpointBackAfterAKill) {
  {
    std::unique_ptr<Workspace> ws;
    ASSERT_TRUE(Workspace::Open(root_, Workspace::Mode::kReadWrite, &ws).ok());
    fs::path staging;
    bool resumed = true;
    ASSERT_TRUE(ws->BeginStage("train", "f", {}, true, &staging, &resumed).ok());
    EXPECT_FALSE(resumed);
    ASSERT_TRUE(WriteFileAtomic(staging / "checkpoint.txt", "step 40").ok());
    // Killed here: the record says running and nobody holds the lock.
  }
  std::unique_ptr<Workspace> ws;
  ASSERT_TRUE(Workspace::Open(root_, Workspace::Mode::kReadWrite, &ws).ok());
  std::string seen;
  bool was_resumed = false, skipped = true;
  const StageBody body = [&](const StageContext& context, StageResult* result) {
    was_resumed = context.resumed;
    seen.clear();
    ReadFileToString(context.staging / "checkpoint.txt", &seen).ok();
    return WriteOutput(context.staging, result, "trained");
  };
  ASSERT_TRUE(RunStage(ws.get(), {"train", "f", "", /*resumable=*/true}, body, &skipped).ok());
  EXPECT_TRUE(was_resumed);
  EXPECT_EQ(seen, "step 40");
  EXPECT_EQ(ws->Find("train")->status, StageStatus::kDone);

  // Killed again, then rerun with other options: a clean start.
  fs::path staging;
  bool resumed = false;
  ASSERT_TRUE(ws->BeginStage("train", "g", {}, true, &staging, &resumed).ok());
  ASSERT_TRUE(WriteFileAtomic(staging / "checkpoint.txt", "step 7").ok());
  ws.reset();
  ASSERT_TRUE(Workspace::Open(root_, Workspace::Mode::kReadWrite, &ws).ok());
  ASSERT_TRUE(RunStage(ws.get(), {"train", "h", "", true}, body, &skipped).ok());
  EXPECT_FALSE(was_resumed);
  EXPECT_EQ(seen, "");
}

TEST_F(WorkspaceTest, InterruptedStageKeepsItsFolderAndIsNotResumedUnlessResumable) {
  std::unique_ptr<Workspace> ws;
  ASSERT_TRUE(Workspace::Open(root_, Workspace::Mode::kReadWrite, &ws).ok());
  bool skipped = false;
  const Status stopped = RunStage(
      ws.get(), {"train", "f", "", true},
      [](const StageContext& context, StageResult*) {
        EXPECT_TRUE(WriteFileAtomic(context.staging / "checkpoint.txt", "step 3").ok());
        return Status::Interrupted("stopped at step 3");
      },
      &skipped);
  EXPECT_EQ(stopped.code(), Status::Code::kInterrupted);
  EXPECT_EQ(ws->Find("train")->status, StageStatus::kInterrupted);
  EXPECT_TRUE(fs::exists(root_ / ".staging" / "train" / "checkpoint.txt"));
  EXPECT_FALSE(fs::exists(root_ / "failed" / "train"));

  bool resumed = false;
  const StageBody look = [&](const StageContext& context, StageResult* result) {
    resumed = context.resumed && fs::exists(context.staging / "checkpoint.txt");
    return WriteOutput(context.staging, result, "x");
  };
  ASSERT_TRUE(RunStage(ws.get(), {"train", "f", "", true}, look, &skipped).ok());
  EXPECT_TRUE(resumed);

  // A stage that keeps no checkpoints is redone from an empty folder.
  RunStage(ws.get(), {"track", "f", ""},
           [](const StageContext& context, StageResult*) {
             EXPECT_TRUE(WriteFileAtomic(context.staging / "half.txt", "half").ok());
             return Status::Interrupted("stopped");
           },
           &skipped);
  ASSERT_TRUE(RunStage(ws.get(), {"track", "f", ""},
                       [&](const StageContext& context, StageResult* result) {
                         EXPECT_FALSE(context.resumed);
                         EXPECT_FALSE(fs::exists(context.staging / "half.txt"));
                         return WriteOutput(context.staging, result, "y");
                       },
                       &skipped)
                  .ok());
}

// Runs stage `name` with a body that writes <name>.out and counts the stage's
// runs in `runs`; says whether it was skipped as up to date.
bool RunCountingStage(Workspace* ws, std::map<std::string, int>* runs, const std::string& name,
                      const std::string& fingerprint, std::vector<std::string> upstream, bool force = false) {
  StageRun run{name, fingerprint, "", false, force, upstream};
  bool skipped = false;
  const Status s = RunStage(ws, run,
                            Body([&, name](const fs::path& staging, StageResult* result) {
                              ++(*runs)[name];
                              HF_RETURN_IF_ERROR(WriteFileAtomic(staging / (name + ".out"), "x"));
                              result->outputs = {name + ".out"};
                              return Status::Ok();
                            }),
                            &skipped);
  EXPECT_TRUE(s.ok()) << s.message();
  return skipped;
}

// Runs a resumable train stage (read from ingest) that writes a checkpoint,
// then stops when `stop` or else finishes; `resumed`: whether its staging
// folder came back with a checkpoint.
Status RunCheckpointingTrain(Workspace* ws, bool stop, bool* resumed, bool* skipped) {
  StageRun run{"train", "r", "", /*resumable=*/true, false, {"ingest"}};
  return RunStage(ws, run,
                  [&](const StageContext& context, StageResult* result) {
                    *resumed = context.resumed;
                    HF_RETURN_IF_ERROR(WriteFileAtomic(context.staging / "model", "m"));
                    if (stop) return Status::Interrupted("stopped");
                    result->outputs = {"model"};
                    return Status::Ok();
                  },
                  skipped);
}

// A stage whose upstream stage is run again (new outputs, even with the same
// fingerprint) is out of date: reported, never skipped, and current again
// once redone. A failed attempt upstream leaves its outputs, so nothing goes
// out of date; a manifest from before the check says nothing is.
TEST_F(WorkspaceTest, StageIsOutOfDateWhenAnUpstreamStageRunsAgain) {
  std::unique_ptr<Workspace> ws;
  ASSERT_TRUE(Workspace::Open(root_, Workspace::Mode::kReadWrite, &ws).ok());
  std::map<std::string, int> runs;
  auto stage = [&](const std::string& name, const std::string& fingerprint, std::vector<std::string> upstream,
                   bool force = false) { return RunCountingStage(ws.get(), &runs, name, fingerprint, upstream, force); };
  stage("ingest", "i1", {});
  stage("calibrate", "c", {"ingest"});
  stage("track", "t", {"ingest", "calibrate"});
  for (const char* name : {"ingest", "calibrate", "track"}) EXPECT_EQ(ws->OutOfDate(name), "") << name;
  EXPECT_TRUE(stage("calibrate", "c", {"ingest"}));  // up to date: skipped

  stage("ingest", "i2", {});  // new inputs
  EXPECT_EQ(ws->OutOfDate("ingest"), "");
  EXPECT_EQ(ws->OutOfDate("calibrate"), "ingest was run again after it");
  EXPECT_EQ(ws->OutOfDate("track"), "ingest was run again after it");
  EXPECT_FALSE(ws->IsUpToDate("calibrate", "c"));
  EXPECT_FALSE(stage("calibrate", "c", {"ingest"}));  // same fingerprint, still redone
  EXPECT_EQ(runs["calibrate"], 2);
  EXPECT_EQ(ws->OutOfDate("calibrate"), "");
  EXPECT_EQ(ws->OutOfDate("track"), "ingest was run again after it");  // the first stage it read that changed
  EXPECT_FALSE(stage("track", "t", {"ingest", "calibrate"}));
  EXPECT_EQ(ws->OutOfDate("track"), "");

  stage("calibrate", "c", {"ingest"}, /*force=*/true);  // same fingerprint, new outputs
  EXPECT_EQ(ws->OutOfDate("track"), "calibrate was run again after it");
  // Redone from new upstream outputs, track's outputs are new although its
  // fingerprint is not: a stage that read the earlier ones sees it.
  stage("train", "x", {"ingest", "calibrate", "track"});  // (RunStage alone does not refuse it)
  const long track_before = ws->Find("track")->commit;
  EXPECT_FALSE(stage("track", "t", {"ingest", "calibrate"}));
  EXPECT_NE(ws->Find("track")->commit, track_before);
  EXPECT_EQ(ws->OutOfDate("train"), "track was run again after it");
  EXPECT_FALSE(stage("train", "x", {"ingest", "calibrate", "track"}));
  EXPECT_EQ(ws->OutOfDate("train"), "");
  EXPECT_EQ(ws->OutputsOutOfDate("train"), "");
  // A failed attempt after track ran again leaves the older model in place:
  // the stage is not done, and its outputs are still older than the tracking.
  stage("track", "t", {"ingest", "calibrate"}, /*force=*/true);
  bool failed_skip = false;
  EXPECT_FALSE(RunStage(ws.get(), {"train", "x", "", false, false, {"ingest", "calibrate", "track"}},
                        Body([](const fs::path&, StageResult*) { return Status::DataError("NaN"); }), &failed_skip)
                   .ok());
  EXPECT_EQ(ws->OutOfDate("train"), "");
  EXPECT_EQ(ws->OutputsOutOfDate("train"), "track was run again after it");
  EXPECT_FALSE(stage("train", "x", {"ingest", "calibrate", "track"}));
  EXPECT_EQ(ws->OutputsOutOfDate("train"), "");

  bool skipped = false;
  EXPECT_FALSE(RunStage(ws.get(), {"ingest", "i3", ""},
                        Body([](const fs::path&, StageResult*) { return Status::DataError("no face"); }), &skipped)
                   .ok());
  EXPECT_EQ(ws->OutOfDate("calibrate"), "");  // ingest's outputs are still the ones calibrate read
  EXPECT_EQ(ws->OutOfDate("track"), "");
  // Redone with the inputs its outputs were made from (the failed attempt's
  // were others): the same outputs, so the same number.
  EXPECT_FALSE(stage("ingest", "i2", {}));
  EXPECT_EQ(ws->OutOfDate("calibrate"), "");
  EXPECT_EQ(ws->OutOfDate("track"), "");

  // Its outputs deleted, a stage is redone with the same fingerprint from the
  // same upstream outputs: a repeatable one keeps its number, one that is not
  // (COLMAP) makes what read its earlier outputs out of date.
  fs::remove(root_ / "calibrate.out");
  EXPECT_FALSE(stage("calibrate", "c", {"ingest"}));
  EXPECT_EQ(ws->OutOfDate("track"), "");
  fs::remove(root_ / "calibrate.out");
  ASSERT_TRUE(RunStage(ws.get(), {"calibrate", "c", "", false, false, {"ingest"}},
                       Body([](const fs::path& staging, StageResult* result) {
                         result->outputs = {"calibrate.out"};
                         result->repeatable = false;
                         return WriteFileAtomic(staging / "calibrate.out", "another model");
                       }),
                       &skipped)
                  .ok());
  EXPECT_FALSE(skipped);
  EXPECT_EQ(ws->OutOfDate("track"), "calibrate was run again after it");
  EXPECT_FALSE(stage("track", "t", {"ingest", "calibrate"}));
  EXPECT_EQ(ws->OutOfDate("track"), "");

  // A checkpoint made from outputs an upstream stage has replaced since is
  // not resumed, even with the same fingerprint.
  auto train = [&](bool stop, bool* resumed) { return RunCheckpointingTrain(ws.get(), stop, resumed, &skipped); };
  bool resumed = true;
  EXPECT_EQ(train(true, &resumed).code(), Status::Code::kInterrupted);
  EXPECT_FALSE(resumed);
  ASSERT_TRUE(train(true, &resumed).code() == Status::Code::kInterrupted);
  EXPECT_TRUE(resumed);  // nothing upstream changed: its checkpoint comes back
  stage("ingest", ws->Find("ingest")->fingerprint, {}, /*force=*/true);
  ASSERT_TRUE(train(false, &resumed).ok());
  EXPECT_FALSE(resumed);

  // The numbers persist.
  stage("ingest", "i4", {});
  ws.reset();
  std::unique_ptr<Workspace> reopened;
  ASSERT_TRUE(Workspace::Open(root_, Workspace::Mode::kReadOnly, &reopened).ok());
  EXPECT_EQ(reopened->OutOfDate("track"), "ingest was run again after it");
  ASSERT_NE(reopened->Find("track"), nullptr);
  EXPECT_EQ(reopened->Find("track")->made_from.size(), 2u);
  reopened.reset();

  // A manifest written before stages recorded what they were made from.
  ASSERT_TRUE(WriteFileAtomic(root_ / "workspace.json",
                              R"({"version": 1, "stages": [{"name": "ingest", "status": "done", "fingerprint": "a"},
                                  {"name": "calibrate", "status": "done", "fingerprint": "b"}]})")
                  .ok());
  ASSERT_TRUE(Workspace::Open(root_, Workspace::Mode::kReadWrite, &ws).ok());
  EXPECT_EQ(ws->OutOfDate("calibrate"), "");
  // Skipped as up to date, it records what it was made from; from then on a
  // new ingest makes it out of date.
  EXPECT_TRUE(stage("calibrate", "b", {"ingest"}));
  ASSERT_EQ(ws->Find("calibrate")->made_from.size(), 1u);
  stage("ingest", "a2", {});
  EXPECT_EQ(ws->OutOfDate("calibrate"), "ingest was run again after it");
  ws.reset();

  // One written with made_from but before committed_from: a done stage's
  // outputs were made from what it started from, and stay so after a
  // failed attempt.
  ASSERT_TRUE(WriteFileAtomic(root_ / "workspace.json",
                              R"({"version": 1, "commits": 2, "stages": [
                                  {"name": "ingest", "status": "done", "fingerprint": "a", "commit": 1,
                                   "committed_fingerprint": "a", "outputs": ["ingest.out"]},
                                  {"name": "train", "status": "done", "fingerprint": "x", "commit": 2,
                                   "committed_fingerprint": "x", "made_from": [{"stage": "ingest", "commit": 1}]}]})")
                  .ok());
  ASSERT_TRUE(Workspace::Open(root_, Workspace::Mode::kReadWrite, &ws).ok());
  stage("ingest", "a3", {});
  EXPECT_FALSE(RunStage(ws.get(), {"train", "x", "", false, false, {"ingest"}},
                        Body([](const fs::path&, StageResult*) { return Status::DataError("NaN"); }), &skipped)
                   .ok());
  EXPECT_EQ(ws->OutputsOutOfDate("train"), "ingest was run again after it");
}

TEST_F(WorkspaceTest, SecondWriterIsRefused) {
  std::unique_ptr<Workspace> first, second;
  ASSERT_TRUE(Workspace::Open(root_, Workspace::Mode::kReadWrite, &first).ok());
  const Status status = Workspace::Open(root_, Workspace::Mode::kReadWrite, &second);
  EXPECT_FALSE(status.ok());
  EXPECT_NE(status.message().find("in use"), std::string::npos);
}

TEST_F(WorkspaceTest, DamagedManifestIsReported) {
  ASSERT_TRUE(WriteFileAtomic(root_ / "workspace.json", "{not json").ok());
  std::unique_ptr<Workspace> ws;
  const Status status = Workspace::Open(root_, Workspace::Mode::kReadOnly, &ws);
  EXPECT_EQ(status.code(), Status::Code::kDataError);
}

}  // namespace
}  // namespace headforge
