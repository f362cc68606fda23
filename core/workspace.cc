#include "core/workspace.h"

#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <ctime>
#include <nlohmann/json.hpp>

#include "core/log.h"

namespace headforge {
namespace {

constexpr const char* kManifest = "workspace.json";
constexpr const char* kLockFile = ".lock";
constexpr const char* kStagingDir = ".staging";
constexpr const char* kFailedDir = "failed";
constexpr int kManifestVersion = 1;

StageStatus ParseStatus(const std::string& text) {
  if (text == "running") return StageStatus::kRunning;
  if (text == "done") return StageStatus::kDone;
  if (text == "failed") return StageStatus::kFailed;
  if (text == "interrupted") return StageStatus::kInterrupted;
  return StageStatus::kPending;
}

}  // namespace

const char* StageStatusName(StageStatus status) {
  switch (status) {
    case StageStatus::kPending: return "pending";
    case StageStatus::kRunning: return "running";
    case StageStatus::kDone: return "done";
    case StageStatus::kFailed: return "failed";
    case StageStatus::kInterrupted: return "interrupted";
  }
  return "pending";
}

std::string NowIso8601() {
  const std::time_t now = std::time(nullptr);
  std::tm tm{};
  gmtime_r(&now, &tm);
  char text[32];
  std::strftime(text, sizeof(text), "%Y-%m-%dT%H:%M:%SZ", &tm);
  return text;
}

Status Workspace::Open(const fs::path& root, Mode mode, std::unique_ptr<Workspace>* workspace) {
  std::unique_ptr<Workspace> ws(new Workspace());
  ws->root_ = AbsolutePath(root);
  ws->mode_ = mode;
  std::error_code ec;
  if (mode == Mode::kReadOnly) {
    if (!fs::exists(ws->root_ / kManifest, ec))
      return Status::NotFound("no workspace at " + root.string() + " (no " + kManifest + ")");
  } else {
    if (fs::exists(ws->root_, ec) && !fs::is_directory(ws->root_, ec))
      return Status::InvalidArgument("workspace path is a file, not a folder: " + root.string());
    HF_RETURN_IF_ERROR(EnsureDirectory(ws->root_));
    const fs::path lock_path = ws->root_ / kLockFile;
    ws->lock_fd_ = ::open(lock_path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
    if (ws->lock_fd_ < 0)
      return Status::IoError("cannot create lock file " + lock_path.string());
    if (::flock(ws->lock_fd_, LOCK_EX | LOCK_NB) != 0)
      return Status::InvalidArgument("workspace " + root.string() +
                                     " is in use by another headforge process; wait for it "
                                     "to finish or stop it");
  }
  HF_RETURN_IF_ERROR(ws->Load());
  if (mode == Mode::kReadWrite && !fs::exists(ws->root_ / kManifest, ec)) HF_RETURN_IF_ERROR(ws->Save());
  *workspace = std::move(ws);
  return Status::Ok();
}

bool Workspace::Exists(const fs::path& root) {
  std::error_code ec;
  return fs::exists(root / kManifest, ec);
}

Workspace::~Workspace() {
  if (lock_fd_ >= 0) ::close(lock_fd_);  // releases the flock
}

Status Workspace::Load() {
  records_.clear();
  const fs::path path = root_ / kManifest;
  std::error_code ec;
  if (!fs::exists(path, ec)) return Status::Ok();
  std::string text;
  HF_RETURN_IF_ERROR(ReadFileToString(path, &text));
  nlohmann::json manifest;
  try {
    manifest = nlohmann::json::parse(text);
    for (const auto& stage : manifest.at("stages")) {
      StageRecord record;
      record.name = stage.at("name").get<std::string>();
      record.status = ParseStatus(stage.value("status", "pending"));
      record.fingerprint = stage.value("fingerprint", "");
      record.outputs = stage.value("outputs", std::vector<std::string>{});
      record.wall_time_s = stage.value("wall_time_s", 0.0);
      record.started_at = stage.value("started_at", "");
      record.finished_at = stage.value("finished_at", "");
      record.message = stage.value("message", "");
      record.commit = stage.value("commit", 0L);
      record.committed_fingerprint = stage.value("committed_fingerprint", "");
      for (const auto& from : stage.value("made_from", nlohmann::json::array()))
        record.made_from.emplace_back(from.at("stage").get<std::string>(), from.at("commit").get<long>());
      for (const auto& from : stage.value("committed_from", nlohmann::json::array()))
        record.committed_from.emplace_back(from.at("stage").get<std::string>(), from.at("commit").get<long>());
      // A record from before committed_from: a done stage's outputs were
      // committed from what it last started from.
      if (!stage.contains("committed_from") && record.status == StageStatus::kDone)
        record.committed_from = record.made_from;
      records_.push_back(record);
    }
    commits_ = manifest.value("commits", 0L);
  } catch (const nlohmann::json::exception& e) {
    return Status::DataError(path.string() + " is damaged (" + e.what() +
                             "); move it away to start the workspace afresh");
  }
  return Status::Ok();
}

Status Workspace::Save() const {
  HF_CHECK(mode_ == Mode::kReadWrite);
  nlohmann::json manifest;
  manifest["version"] = kManifestVersion;
  manifest["commits"] = commits_;
  manifest["stages"] = nlohmann::json::array();
  for (const auto& r : records_) {
    auto commits = [](const std::vector<std::pair<std::string, long>>& list) {
      nlohmann::json out = nlohmann::json::array();
      for (const auto& [name, commit] : list) out.push_back({{"stage", name}, {"commit", commit}});
      return out;
    };
    manifest["stages"].push_back({{"name", r.name},
                                  {"status", StageStatusName(r.status)},
                                  {"fingerprint", r.fingerprint},
                                  {"outputs", r.outputs},
                                  {"wall_time_s", r.wall_time_s},
                                  {"started_at", r.started_at},
                                  {"finished_at", r.finished_at},
                                  {"message", r.message},
                                  {"commit", r.commit},
                                  {"committed_fingerprint", r.committed_fingerprint},
                                  {"made_from", commits(r.made_from)},
                                  {"committed_from", commits(r.committed_from)}});
  }
  return WriteFileAtomic(root_ / kManifest, manifest.dump(2) + "\n");
}

std::vector<StageRecord> Workspace::Stages(const std::vector<std::string>& order) const {
  std::vector<StageRecord> ordered;
  for (const auto& name : order) {
    if (const StageRecord* r = Find(name)) {
      ordered.push_back(*r);
    } else {
      StageRecord pending;
      pending.name = name;
      ordered.push_back(pending);
    }
  }
  for (const auto& r : records_) {
    if (std::find(order.begin(), order.end(), r.name) == order.end()) ordered.push_back(r);
  }
  return ordered;
}

const StageRecord* Workspace::Find(const std::string& stage) const {
  for (const auto& r : records_)
    if (r.name == stage) return &r;
  return nullptr;
}

StageRecord* Workspace::Mutable(const std::string& stage) {
  for (auto& r : records_)
    if (r.name == stage) return &r;
  records_.emplace_back();
  records_.back().name = stage;
  return &records_.back();
}

namespace {

// The first stage of `made_from` committed again since, said; "" if none.
std::string NewerUpstream(const Workspace& workspace, const std::vector<std::pair<std::string, long>>& made_from) {
  for (const auto& [name, commit] : made_from) {
    const StageRecord* u = workspace.Find(name);
    if (!u || u->commit == commit) continue;
    return name + " was run again after it";
  }
  return "";
}

}  // namespace

std::string Workspace::OutOfDate(const std::string& stage) const {
  const StageRecord* r = Find(stage);
  if (!r || r->status != StageStatus::kDone) return "";
  return NewerUpstream(*this, r->made_from);
}

std::string Workspace::OutputsOutOfDate(const std::string& stage) const {
  const StageRecord* r = Find(stage);
  if (!r) return "";
  if (!r->committed_from.empty()) return NewerUpstream(*this, r->committed_from);
  return OutOfDate(stage);  // a record from before committed_from: known only while done
}

std::vector<std::pair<std::string, long>> Workspace::UpstreamCommits(const std::vector<std::string>& upstream) const {
  std::vector<std::pair<std::string, long>> commits;
  for (const std::string& name : upstream) {
    const StageRecord* u = Find(name);
    commits.emplace_back(name, u ? u->commit : 0);
  }
  return commits;
}

bool Workspace::IsUpToDate(const std::string& stage, const std::string& fingerprint) const {
  const StageRecord* r = Find(stage);
  if (!r || r->status != StageStatus::kDone || r->fingerprint != fingerprint || !OutOfDate(stage).empty()) return false;
  std::error_code ec;
  for (const auto& output : r->outputs)
    if (!fs::exists(root_ / output, ec)) return false;
  return true;
}

bool Workspace::WasInterrupted(const std::string& stage) const {
  const StageRecord* r = Find(stage);
  if (!r || r->status != StageStatus::kRunning) return false;
  if (lock_fd_ >= 0) return true;  // we hold the lock, so nobody else is running it
  const fs::path lock_path = root_ / kLockFile;
  const int fd = ::open(lock_path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return true;
  const bool free = ::flock(fd, LOCK_SH | LOCK_NB) == 0;
  ::close(fd);
  return free;
}

fs::path Workspace::StagingPath(const fs::path& root, const std::string& stage) { return root / kStagingDir / stage; }

Status Workspace::BeginStage(const std::string& stage, const std::string& fingerprint,
                             const std::vector<std::string>& upstream, bool resumable, fs::path* staging,
                             bool* resumed) {
  HF_CHECK(mode_ == Mode::kReadWrite);
  *staging = StagingPath(root_, stage);
  // We hold the lock, so a record that says running belongs to a run that died.
  const StageRecord* last = Find(stage);
  const std::vector<std::pair<std::string, long>> made_from = UpstreamCommits(upstream);
  // A checkpoint made from other upstream outputs (the same fingerprint, an
  // upstream stage run again since) is not resumed; one from before records
  // said what they were made from is.
  std::error_code ec;
  *resumed = resumable && last != nullptr && last->fingerprint == fingerprint &&
             (last->made_from.empty() || last->made_from == made_from) &&
             (last->status == StageStatus::kRunning || last->status == StageStatus::kInterrupted) &&
             fs::is_directory(*staging, ec);
  if (!*resumed) HF_RETURN_IF_ERROR(RemoveAll(*staging));  // leftovers of an interrupted attempt
  HF_RETURN_IF_ERROR(RemoveAll(root_ / kFailedDir / stage));  // an earlier failure's files
  StageRecord* r = Mutable(stage);
  // Made from other upstream outputs, its outputs will be new ones even with
  // the same fingerprint: CommitStage numbers them afresh.
  if (!r->made_from.empty() && r->made_from != made_from) r->committed_fingerprint.clear();
  r->status = StageStatus::kRunning;
  r->fingerprint = fingerprint;
  r->made_from = made_from;
  r->started_at = NowIso8601();
  r->finished_at.clear();
  r->message.clear();
  // The record says running before the staging folder exists, so that a run
  // killed in between is seen as interrupted, never as a pending stage with
  // a staging folder.
  HF_RETURN_IF_ERROR(Save());
  if (Status made = EnsureDirectory(*staging); !made.ok()) {
    std::string message = made.message();
    (void)FailStage(stage, &message, 0.0);  // the error below is the one to report
    return made;
  }
  return Status::Ok();
}

Status Workspace::CommitStage(const std::string& stage, const std::vector<std::string>& outputs,
                              double wall_time_s, const std::string& message, bool forced) {
  HF_CHECK(mode_ == Mode::kReadWrite);
  const fs::path staging = StagingPath(root_, stage);
  for (const auto& output : outputs) {
    std::error_code ec;
    if (!fs::exists(staging / output, ec))
      return Status::Internal("stage " + stage + " did not write its output " + output);
  }
  for (const auto& output : outputs) HF_RETURN_IF_ERROR(ReplacePath(staging / output, root_ / output));
  HF_RETURN_IF_ERROR(RemoveAll(staging));
  StageRecord* r = Mutable(stage);
  r->status = StageStatus::kDone;
  if (forced || r->commit == 0 || r->committed_fingerprint != r->fingerprint) r->commit = ++commits_;
  r->committed_fingerprint = r->fingerprint;
  r->committed_from = r->made_from;
  r->outputs = outputs;
  r->wall_time_s = wall_time_s;
  r->finished_at = NowIso8601();
  r->message = message;
  return Save();
}

Status Workspace::RecordMadeFrom(const std::string& stage, const std::vector<std::string>& upstream) {
  HF_CHECK(mode_ == Mode::kReadWrite);
  StageRecord* r = Mutable(stage);
  const bool fill_made_from = r->made_from.empty() && !upstream.empty();
  if (fill_made_from) r->made_from = UpstreamCommits(upstream);
  // Up to date, its outputs were committed from what it was made from.
  const bool fill_committed = r->committed_from.empty() && !r->made_from.empty() && r->status == StageStatus::kDone;
  if (fill_committed) r->committed_from = r->made_from;
  return fill_made_from || fill_committed ? Save() : Status::Ok();
}

Status Workspace::FailStage(const std::string& stage, std::string* message, double wall_time_s) {
  HF_CHECK(mode_ == Mode::kReadWrite);
  const fs::path staging = StagingPath(root_, stage);
  // Keep what the attempt wrote, unless that is only its options file.
  std::error_code ec;
  bool wrote = false;
  for (const auto& entry : fs::directory_iterator(staging, ec))
    if (entry.path().filename() != stage + ".ini") wrote = true;
  const fs::path kept = root_ / kFailedDir / stage;
  if (wrote && EnsureDirectory(kept.parent_path()).ok() && ReplacePath(staging, kept).ok()) {
    const std::string from = staging.string(), to = kept.string();
    for (size_t at = message->find(from); at != std::string::npos; at = message->find(from, at + to.size()))
      message->replace(at, from.size(), to);
    if (message->find(to) == std::string::npos) *message += " (what the failed attempt wrote is kept in " + to + ")";
  }
  RemoveAll(staging);
  StageRecord* r = Mutable(stage);
  r->status = StageStatus::kFailed;
  r->wall_time_s = wall_time_s;
  r->finished_at = NowIso8601();
  r->message = *message;
  return Save();
}

Status Workspace::InterruptStage(const std::string& stage, const std::string& message, double wall_time_s) {
  HF_CHECK(mode_ == Mode::kReadWrite);
  StageRecord* r = Mutable(stage);
  r->status = StageStatus::kInterrupted;
  r->wall_time_s = wall_time_s;
  r->finished_at = NowIso8601();
  r->message = message;
  return Save();
}

Status RunStage(Workspace* workspace, const StageRun& run, const StageBody& body, bool* skipped) {
  const std::string& stage = run.name;
  if (!run.force && workspace->IsUpToDate(stage, run.fingerprint)) {
    HF_LOG(Info) << stage << ": up to date (inputs and options unchanged), skipped";
    *skipped = true;
    return workspace->RecordMadeFrom(stage, run.upstream);
  }
  *skipped = false;
  if (const std::string why = workspace->OutOfDate(stage); !why.empty() && !run.force)
    HF_LOG(Info) << stage << ": out of date (" << why << "), redoing it";
  const bool cut_short = workspace->WasInterrupted(stage) ||
                         (workspace->Find(stage) && workspace->Find(stage)->status == StageStatus::kInterrupted);
  StageContext context;
  HF_RETURN_IF_ERROR(workspace->BeginStage(stage, run.fingerprint, run.upstream, run.resumable && !run.force,
                                           &context.staging, &context.resumed));
  if (context.resumed) {
    HF_LOG(Info) << stage << ": an earlier run was interrupted; resuming from its checkpoint";
  } else if (cut_short) {
    HF_LOG(Info) << stage << ": an earlier run was interrupted; redoing the stage";
  }
  const fs::path& staging = context.staging;
  const auto start = std::chrono::steady_clock::now();
  auto seconds = [&] {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  };
  StageResult result;
  Status status = WriteFileAtomic(staging / (stage + ".ini"), run.options_ini);
  if (status.ok()) {
    try {
      status = body(context, &result);
    } catch (const std::exception& e) {
      status = Status::Internal(e.what());
    }
  }
  if (status.code() == Status::Code::kInterrupted) {
    workspace->InterruptStage(stage, status.message(), seconds());
    return status.WithContext(stage);
  }
  // A resumable stage that could not write (a full disk) keeps its staging
  // and checkpoint, as an interruption does: with room again it resumes.
  if (status.code() == Status::Code::kIoError && run.resumable) {
    const std::string message = status.message() + "; the next run goes on from the stage's last checkpoint";
    workspace->InterruptStage(stage, message, seconds());
    return status.WithMessage(message).WithContext(stage);
  }
  if (!status.ok()) {
    std::string message = status.message();
    workspace->FailStage(stage, &message, seconds());
    return status.WithMessage(message).WithContext(stage);
  }
  result.outputs.push_back(stage + ".ini");
  return workspace->CommitStage(stage, result.outputs, seconds(), result.message, run.force || !result.repeatable);
}

}  // namespace headforge
