#include "pipelines/batch_manifest.h"

#include <algorithm>
#include <set>
#include <sstream>

namespace headforge {
namespace {

std::vector<std::string> SplitTabs(const std::string& line) {
  std::vector<std::string> fields;
  size_t start = 0;
  while (true) {
    const size_t tab = line.find('\t', start);
    fields.push_back(line.substr(start, tab == std::string::npos ? std::string::npos : tab - start));
    if (tab == std::string::npos) break;
    start = tab + 1;
  }
  return fields;
}

// An input or config given in the manifest, absolute (relative to `base`);
// "" and `*why` when it does not exist.
std::string ExistingPath(const std::string& field, const fs::path& base, const std::string& what, std::string* why) {
  const fs::path path = AbsolutePath(fs::path(field).is_absolute() ? fs::path(field) : base / field);
  std::error_code ec;
  if (!fs::exists(path, ec)) {
    *why = what + " not found: " + path.string();
    return "";
  }
  return path.string();
}

// One row's fields checked; `*why` says what is wrong with it.
BatchRow ParseRow(const std::vector<std::string>& fields, const fs::path& base, const std::vector<std::string>& presets,
                  std::string* why) {
  BatchRow row;
  row.name = fields[0];
  if (fields.size() < 4) {
    *why = "needs name, preset, config and at least one input, tab-separated (" + std::to_string(fields.size()) +
           " field(s))";
    return row;
  }
  if (const std::string bad = BadCaptureName(row.name); !bad.empty()) {
    *why = "bad name: " + bad;
    return row;
  }
  row.preset = fields[1];
  if (!row.preset.empty() && std::find(presets.begin(), presets.end(), row.preset) == presets.end()) {
    std::string known;
    for (const auto& p : presets) known += (known.empty() ? "" : ", ") + p;
    *why = "unknown preset '" + row.preset + "' (the presets: " + known + ")";
    return row;
  }
  if (!fields[2].empty() && fields[2] != "-") {
    row.config = ExistingPath(fields[2], base, "config", why);
    if (row.config.empty()) return row;
  }
  for (size_t i = 3; i < fields.size(); ++i) {
    if (fields[i].empty()) continue;  // a trailing tab
    const std::string input = ExistingPath(fields[i], base, "input", why);
    if (input.empty()) return row;
    row.inputs.push_back(input);
  }
  if (row.inputs.empty()) *why = "no input (a video or image folder per camera)";
  return row;
}

}  // namespace

std::string BadCaptureName(const std::string& name) {
  if (name.empty()) return "empty";
  if (name == "." || name == "..") return "'" + name + "' is not a folder name";
  if (name.find('/') != std::string::npos) return "'/' in a name (a name is one folder)";
  if (name[0] == '.') return "a name may not start with '.' (the batch keeps its own files in .batch)";
  if (name[0] == '-') return "a name may not start with '-'";
  for (const char c : name)
    if (static_cast<unsigned char>(c) < 0x20 || c == 0x7f) return "a control character in the name";
  return "";
}

Status ParseManifest(const std::string& text, const fs::path& base, const std::string& source,
                     const std::vector<std::string>& presets, std::vector<BatchRow>* rows) {
  rows->clear();
  std::vector<BatchRow> parsed;
  std::set<std::string> names;
  std::string errors;
  std::istringstream lines(text);
  int number = 0;
  for (std::string line; std::getline(lines, line);) {
    ++number;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (line.find_first_not_of(" \t") == std::string::npos || line[0] == '#') continue;
    std::string why;
    BatchRow row = ParseRow(SplitTabs(line), base, presets, &why);
    row.line = number;
    if (why.empty() && !names.insert(row.name).second) why = "duplicate name (an earlier row has it)";
    if (!why.empty()) {
      errors += "\n  " + source + " line " + std::to_string(number) + " (" + row.name + "): " + why;
      continue;
    }
    parsed.push_back(std::move(row));
  }
  if (!errors.empty()) return Status::InvalidArgument("batch: bad rows in the manifest, nothing submitted:" + errors);
  if (parsed.empty()) return Status::InvalidArgument("batch: " + source + " has no rows");
  *rows = std::move(parsed);
  return Status::Ok();
}

Status ReadManifest(const fs::path& manifest, const std::vector<std::string>& presets, std::vector<BatchRow>* rows) {
  std::string text;
  HF_RETURN_IF_ERROR(ReadFileToString(manifest, &text).WithContext("batch: manifest"));
  return ParseManifest(text, AbsolutePath(manifest).parent_path(), manifest.string(), presets, rows);
}

}  // namespace headforge
