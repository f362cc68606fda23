#include "pipelines/batch_slurm.h"

#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <ostream>
#include <sstream>

#include "core/json_io.h"
#include "core/log.h"
#include "core/process.h"

namespace headforge {
namespace {

constexpr int kBatchVersion = 1;

// The value a per-stage option ("VALUE,train=OTHER") gives `stage`.
std::string ForStage(const std::string& spec, const std::string& stage) {
  std::string fallback;
  std::stringstream entries(spec);
  for (std::string entry; std::getline(entries, entry, ',');) {
    const size_t eq = entry.find('=');
    if (eq == std::string::npos) {
      fallback = entry;
    } else if (entry.substr(0, eq) == stage) {
      return entry.substr(eq + 1);
    }
  }
  return fallback;
}

Status CheckPerStage(const std::string& spec, const std::string& flag, const std::vector<std::string>& stages) {
  std::stringstream entries(spec);
  for (std::string entry; std::getline(entries, entry, ',');) {
    const size_t eq = entry.find('=');
    if (eq == std::string::npos) continue;
    const std::string stage = entry.substr(0, eq);
    if (std::find(stages.begin(), stages.end(), stage) == stages.end())
      return Status::InvalidArgument("--" + flag + " names '" + stage + "', not a stage of this batch");
    if (eq + 1 == entry.size()) return Status::InvalidArgument("--" + flag + ": no value for " + stage);
  }
  return Status::Ok();
}

nlohmann::json RowToJson(const BatchRow& row) {
  return {{"line", row.line}, {"name", row.name}, {"preset", row.preset}, {"config", row.config},
          {"inputs", row.inputs}};
}

BatchRow RowFromJson(const nlohmann::json& j) {
  BatchRow row;
  row.line = j.value("line", 0);
  row.name = j.at("name").get<std::string>();
  row.preset = j.value("preset", "");
  row.config = j.value("config", "");
  row.inputs = j.at("inputs").get<std::vector<std::string>>();
  return row;
}

std::string Joined(const std::vector<std::string>& args) {
  std::string line;
  for (const auto& a : args) line += (line.empty() ? "" : " ") + ShellQuote(a);
  return line;
}

// Runs `args` with its output in `capture` (replaced), and returns that output.
Status RunCaptured(const std::vector<std::string>& args, const fs::path& capture, std::string* output,
                   int* exit_code) {
  std::error_code ec;
  fs::remove(capture, ec);
  HF_RETURN_IF_ERROR(RunProgram(args, capture, exit_code));
  const Status read = ReadFileToString(capture, output);
  fs::remove(capture, ec);
  return read;
}

void CancelArrays(const std::map<std::string, std::string>& job_ids, const fs::path& dir) {
  if (job_ids.empty()) return;
  std::vector<std::string> args = {"scancel"};
  for (const auto& [stage, id] : job_ids) args.push_back(id);
  int code = 0;
  if (!RunProgram(args, dir / "scancel.log", &code).ok() || code != 0)
    HF_LOG(Warning) << "batch: scancel of the arrays already submitted failed; see " << (dir / "scancel.log").string();
}

}  // namespace

Status SlurmOptions::Check(const std::vector<std::string>& stages) const {
  HF_RETURN_IF_ERROR(CheckPerStage(partition, "partition", stages));
  HF_RETURN_IF_ERROR(CheckPerStage(time, "time", stages));
  HF_RETURN_IF_ERROR(CheckPerStage(mem, "mem", stages));
  if (cpus_per_task < 0) return Status::InvalidArgument("--cpus-per-task must be >= 0 (0: Slurm's default)");
  if (max_parallel < 0) return Status::InvalidArgument("--max-parallel must be >= 0 (0: no limit)");
  if (signal_seconds < 0 || signal_seconds > 65535)
    return Status::InvalidArgument("--signal-seconds must be in [0, 65535] (0: no warning signal)");
  return Status::Ok();
}

std::string ShellQuote(const std::string& text) {
  const bool plain = !text.empty() && std::all_of(text.begin(), text.end(), [](char c) {
    return std::isalnum(static_cast<unsigned char>(c)) || std::string("/._-=:,%@+").find(c) != std::string::npos;
  });
  if (plain) return text;
  std::string quoted = "'";
  for (const char c : text) quoted += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return quoted + "'";
}

fs::path BatchPlan::Log(const std::string& stage, size_t index) const {
  return Dir() / "logs" / (stage + "_" + std::to_string(index) + ".log");
}

std::vector<std::string> BatchPlan::StageArgs(const std::string& stage, size_t index) const {
  const BatchRow& row = rows.at(index);
  std::vector<std::string> args = {"run", "--until", stage, "--workspace", (root / row.name).string(), "--video"};
  args.insert(args.end(), row.inputs.begin(), row.inputs.end());
  if (!row.config.empty()) args.insert(args.end(), {"--config", row.config});
  if (!row.preset.empty()) args.insert(args.end(), {"--preset", row.preset});
  return args;
}

std::vector<std::string> BatchPlan::SbatchArgs(const std::string& stage, const std::string& after) const {
  std::string array = "0-" + std::to_string(rows.size() - 1);
  if (slurm.max_parallel > 0) array += "%" + std::to_string(slurm.max_parallel);
  // Relative to --chdir: a '%' in the root would be read as a file pattern.
  std::vector<std::string> args = {"sbatch", "--parsable", "--job-name=hf-" + stage + "-" + id, "--array=" + array,
                                   "--chdir=" + Dir().string(), "--output=logs/" + stage + "_%a.log",
                                   "--open-mode=append", "--requeue"};
  if (slurm.signal_seconds > 0) args.push_back("--signal=B:TERM@" + std::to_string(slurm.signal_seconds));
  if (const std::string p = ForStage(slurm.partition, stage); !p.empty()) args.push_back("--partition=" + p);
  if (const std::string t = ForStage(slurm.time, stage); !t.empty()) args.push_back("--time=" + t);
  if (const std::string m = ForStage(slurm.mem, stage); !m.empty()) args.push_back("--mem=" + m);
  if (stage == "train" && !slurm.gres.empty()) args.push_back("--gres=" + slurm.gres);
  if (slurm.cpus_per_task > 0) args.push_back("--cpus-per-task=" + std::to_string(slurm.cpus_per_task));
  if (!after.empty()) args.insert(args.end(), {"--dependency=aftercorr:" + after, "--kill-on-invalid-dep=yes"});
  args.push_back((Dir() / (stage + ".sh")).string());
  return args;
}

std::string BatchPlan::Script(const std::string& stage) const {
  return "#!/bin/sh\n"
         "# headforge batch " + id + ", stage " + stage + ": array element i is capture i of batch.json.\n"
         "exec " + ShellQuote(headforge) + " batch job " + ShellQuote(Dir().string()) + " " + stage + "\n";
}

Status WriteBatchPlan(const BatchPlan& plan) {
  nlohmann::json rows = nlohmann::json::array();
  for (const auto& row : plan.rows) rows.push_back(RowToJson(row));
  const SlurmOptions& s = plan.slurm;
  const nlohmann::json j = {
      {"version", kBatchVersion}, {"id", plan.id}, {"root", plan.root.string()}, {"headforge", plan.headforge},
      {"stages", plan.stages}, {"rows", rows}, {"job_ids", plan.job_ids},
      {"slurm", {{"partition", s.partition}, {"time", s.time}, {"mem", s.mem}, {"gres", s.gres},
                 {"cpus_per_task", s.cpus_per_task}, {"max_parallel", s.max_parallel},
                 {"signal_seconds", s.signal_seconds}}}};
  return WriteJsonAtomic(plan.Dir() / "batch.json", j);
}

Status ReadBatchPlan(const fs::path& batch_dir, BatchPlan* plan) {
  nlohmann::json j;
  HF_RETURN_IF_ERROR(ReadJson(batch_dir / "batch.json", &j));
  if (j.value("version", 0) != kBatchVersion)
    return Status::DataError((batch_dir / "batch.json").string() + ": version " +
                             std::to_string(j.value("version", 0)) + ", this headforge reads " +
                             std::to_string(kBatchVersion));
  try {
    plan->id = j.at("id").get<std::string>();
    plan->root = j.at("root").get<std::string>();
    plan->headforge = j.at("headforge").get<std::string>();
    plan->stages = j.at("stages").get<std::vector<std::string>>();
    plan->rows.clear();
    for (const auto& row : j.at("rows")) plan->rows.push_back(RowFromJson(row));
    plan->job_ids = j.value("job_ids", std::map<std::string, std::string>());
    const nlohmann::json& s = j.at("slurm");
    plan->slurm.partition = s.value("partition", "");
    plan->slurm.time = s.value("time", "");
    plan->slurm.mem = s.value("mem", "");
    plan->slurm.gres = s.value("gres", "");
    plan->slurm.cpus_per_task = s.value("cpus_per_task", 0);
    plan->slurm.max_parallel = s.value("max_parallel", 0);
    plan->slurm.signal_seconds = s.value("signal_seconds", 0);
  } catch (const nlohmann::json::exception& e) {
    return Status::DataError((batch_dir / "batch.json").string() + ": " + e.what());
  }
  return Status::Ok();
}

Status LatestBatch(const fs::path& root, fs::path* batch_dir) {
  std::vector<fs::path> found;
  std::error_code ec;
  for (auto it = fs::directory_iterator(root / ".batch", ec); !ec && it != fs::directory_iterator(); it.increment(ec))
    if (fs::exists(it->path() / "batch.json")) found.push_back(it->path());
  if (found.empty()) return Status::NotFound("batch: no batch under " + (root / ".batch").string());
  *batch_dir = *std::max_element(found.begin(), found.end());
  return Status::Ok();
}

Status SubmitBatch(BatchPlan* plan, bool dry_run, std::ostream& out) {
  out << "batch " << plan->id << ": " << plan->rows.size() << " capture(s), stages";
  for (const auto& s : plan->stages) out << " " << s;
  out << ", workspaces in " << plan->root.string() << "\n";
  if (dry_run) {
    // Each job's arguments as JSON: one string per argument, whatever it holds.
    for (const auto& stage : plan->stages) {
      out << "\n" << (plan->Dir() / (stage + ".sh")).string() << ":\n" << plan->Script(stage);
      out << "submit: " << Joined(plan->SbatchArgs(stage, stage == plan->stages.front() ? "" : "<previous>")) << "\n";
      for (size_t i = 0; i < plan->rows.size(); ++i)
        out << "  [" << i << "] " << nlohmann::json(plan->StageArgs(stage, i)).dump() << "\n";
    }
    return Status::Ok();
  }
  HF_RETURN_IF_ERROR(EnsureDirectory(plan->Dir() / "logs"));
  for (const auto& stage : plan->stages) {
    HF_RETURN_IF_ERROR(WriteFileAtomic(plan->Dir() / (stage + ".sh"), plan->Script(stage)));
    fs::permissions(plan->Dir() / (stage + ".sh"), fs::perms::owner_exec | fs::perms::group_exec, fs::perm_options::add);
  }
  HF_RETURN_IF_ERROR(WriteBatchPlan(*plan));
  std::string previous;
  for (const auto& stage : plan->stages) {
    std::string said;
    int code = 0;
    Status s = RunCaptured(plan->SbatchArgs(stage, previous), plan->Dir() / "sbatch.out", &said, &code);
    std::string id;
    std::istringstream lines(said);
    for (std::string line; std::getline(lines, line);)
      if (!line.empty() && std::isdigit(static_cast<unsigned char>(line[0]))) id = line.substr(0, line.find(';'));
    if (s.ok() && (code != 0 || id.empty()))
      s = Status::IoError("sbatch refused the " + stage + " array (exit " + std::to_string(code) + "): " + said);
    if (!s.ok()) {
      CancelArrays(plan->job_ids, plan->Dir());
      plan->job_ids.clear();
      (void)WriteBatchPlan(*plan);
      return s.WithContext("batch: " + stage);
    }
    plan->job_ids[stage] = id;
    out << stage << ": job array " << id << "\n";
    previous = id;
    HF_RETURN_IF_ERROR(WriteBatchPlan(*plan));
  }
  out << "logs in " << (plan->Dir() / "logs").string() << "; headforge batch status " << ShellQuote(plan->root.string())
      << "\n";
  return Status::Ok();
}

Status QueryQueue(const BatchPlan& plan, std::map<std::string, QueueState>* states) {
  states->clear();
  if (plan.job_ids.empty()) return Status::Ok();
  std::string ids;
  for (const auto& [stage, id] : plan.job_ids) ids += (ids.empty() ? "" : ",") + id;
  const fs::path capture = fs::temp_directory_path() / ("headforge_squeue_" + std::to_string(::getpid()) + ".txt");
  std::string said;
  int code = 0;
  if (Status s = RunCaptured({"squeue", "--noheader", "--array", "--states=all", "--jobs=" + ids, "--format=%i|%T|%r"},
                             capture, &said, &code);
      !s.ok()) {
    HF_LOG(Warning) << "batch: " << s.message() << "; the workspaces alone say where the captures are";
    return Status::Ok();
  }
  // squeue fails on ids it has forgotten (MinJobAge past): nothing is queued.
  if (code != 0) return Status::Ok();
  std::istringstream lines(said);
  for (std::string line; std::getline(lines, line);) {
    const size_t a = line.find('|'), b = line.rfind('|');
    if (a == std::string::npos || a == b || line.find('_') == std::string::npos) continue;
    (*states)[line.substr(0, a)] = {line.substr(a + 1, b - a - 1), line.substr(b + 1)};
  }
  return Status::Ok();
}

}  // namespace headforge
