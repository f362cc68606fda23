#include "core/options.h"

#include <boost/program_options.hpp>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <fstream>
#include <iomanip>
#include <map>
#include <set>
#include <sstream>

namespace headforge {

namespace po = boost::program_options;

std::vector<std::string> SplitCommaList(const std::vector<std::string>& tokens) {
  std::vector<std::string> items;
  for (const auto& token : tokens) {
    std::string current;
    for (char c : token) {
      if (c == ',') {
        if (!current.empty()) items.push_back(current);
        current.clear();
      } else {
        current += c;
      }
    }
    if (!current.empty()) items.push_back(current);
  }
  return items;
}

Status ParseFrameList(const std::vector<std::string>& tokens, int count, std::vector<int>* frames) {
  // A whole number of digits alone (no sign, no space, no trailing text).
  const auto whole = [](const std::string& text, int* value) {
    if (text.empty() || text.size() > 9 || text.find_first_not_of("0123456789") != std::string::npos) return false;
    *value = std::stoi(text);
    return true;
  };
  std::vector<int> out;
  for (const std::string& item : SplitCommaList(tokens)) {
    const std::string usage = "'" + item + "' is not all, N, A-B or A-B:S";
    const size_t dash = item.find('-'), colon = item.find(':');
    int first = 0, last = count - 1, step = 1;
    if (item == "all") {
    } else if (dash == std::string::npos) {
      if (!whole(item, &first)) return Status::InvalidArgument(usage);
      last = first;
    } else {
      const std::string to = item.substr(dash + 1, colon == std::string::npos ? std::string::npos : colon - dash - 1);
      if (!whole(item.substr(0, dash), &first) || !whole(to, &last)) return Status::InvalidArgument(usage);
      if (colon != std::string::npos && (!whole(item.substr(colon + 1), &step) || step < 1))
        return Status::InvalidArgument(usage);
      if (last < first) return Status::InvalidArgument("'" + item + "' runs backwards");
    }
    if (item != "all" && last >= count)
      return Status::InvalidArgument("'" + item + "' names a frame past the last (the frames run 0-" +
                                     std::to_string(count - 1) + ")");
    for (int f = first; f <= last; f += step) out.push_back(f);
  }
  *frames = std::move(out);
  return Status::Ok();
}

namespace internal {
namespace {

Status ExpectOne(const std::vector<std::string>& tokens) {
  if (tokens.size() != 1)
    return Status::InvalidArgument("expected one value, got " + std::to_string(tokens.size()));
  return Status::Ok();
}

template <typename T>
Status ParseNumber(const std::string& text, T* value) {
  std::istringstream in(text);
  T parsed{};
  in >> parsed;
  if (in.fail() || !in.eof()) return Status::InvalidArgument("'" + text + "' is not a number");
  *value = parsed;
  return Status::Ok();
}

std::string FormatDouble(double value) {
  // Whole numbers as whole numbers (30, not the shorter 3e+01).
  if (std::isfinite(value) && value == std::floor(value) && std::abs(value) < 1e15) {
    std::ostringstream whole;
    whole << std::fixed << std::setprecision(0) << value;
    return whole.str() == "-0" ? "0" : whole.str();
  }
  std::ostringstream out;
  out << std::setprecision(17) << value;
  // Shortest text that reads back to the same double.
  for (int precision = 1; precision <= 17; ++precision) {
    std::ostringstream shorter;
    shorter << std::setprecision(precision) << value;
    if (std::stod(shorter.str()) == value) return shorter.str();
  }
  return out.str();
}

}  // namespace

Status ParseTokens(const std::vector<std::string>& tokens, bool* value) {
  HF_RETURN_IF_ERROR(ExpectOne(tokens));
  const std::string& t = tokens[0];
  if (t == "1" || t == "true" || t == "yes" || t == "on") {
    *value = true;
  } else if (t == "0" || t == "false" || t == "no" || t == "off") {
    *value = false;
  } else {
    return Status::InvalidArgument("'" + t + "' is not true or false");
  }
  return Status::Ok();
}
Status ParseTokens(const std::vector<std::string>& tokens, int* value) {
  HF_RETURN_IF_ERROR(ExpectOne(tokens));
  return ParseNumber(tokens[0], value);
}
Status ParseTokens(const std::vector<std::string>& tokens, int64_t* value) {
  HF_RETURN_IF_ERROR(ExpectOne(tokens));
  return ParseNumber(tokens[0], value);
}
Status ParseTokens(const std::vector<std::string>& tokens, double* value) {
  HF_RETURN_IF_ERROR(ExpectOne(tokens));
  HF_RETURN_IF_ERROR(ParseNumber(tokens[0], value));
  if (!std::isfinite(*value)) return Status::InvalidArgument("'" + tokens[0] + "' is not finite");
  return Status::Ok();
}
Status ParseTokens(const std::vector<std::string>& tokens, std::string* value) {
  HF_RETURN_IF_ERROR(ExpectOne(tokens));
  *value = tokens[0];
  return Status::Ok();
}
Status ParseTokens(const std::vector<std::string>& tokens, std::vector<std::string>* value) {
  *value = tokens;
  return Status::Ok();
}
Status ParseTokens(const std::vector<std::string>& tokens, std::vector<int>* value) {
  std::vector<int> parsed;
  for (const auto& item : SplitCommaList(tokens)) {
    int number = 0;
    HF_RETURN_IF_ERROR(ParseNumber(item, &number));
    parsed.push_back(number);
  }
  *value = parsed;
  return Status::Ok();
}
Status ParseTokens(const std::vector<std::string>& tokens, std::vector<double>* value) {
  std::vector<double> parsed;
  for (const auto& item : SplitCommaList(tokens)) {
    double number = 0;
    HF_RETURN_IF_ERROR(ParseNumber(item, &number));
    parsed.push_back(number);
  }
  *value = parsed;
  return Status::Ok();
}

std::vector<std::string> FormatTokens(const bool& v) { return {v ? "true" : "false"}; }
std::vector<std::string> FormatTokens(const int& v) { return {std::to_string(v)}; }
std::vector<std::string> FormatTokens(const int64_t& v) { return {std::to_string(v)}; }
std::vector<std::string> FormatTokens(const double& v) { return {FormatDouble(v)}; }
std::vector<std::string> FormatTokens(const std::string& v) { return {v}; }
std::vector<std::string> FormatTokens(const std::vector<std::string>& v) { return v; }
std::vector<std::string> FormatTokens(const std::vector<int>& v) {
  std::vector<std::string> out;
  for (int x : v) out.push_back(std::to_string(x));
  return out;
}
std::vector<std::string> FormatTokens(const std::vector<double>& v) {
  std::vector<std::string> out;
  for (double x : v) out.push_back(FormatDouble(x));
  return out;
}

const char* TypeName(const bool*) { return "bool"; }
const char* TypeName(const int*) { return "int"; }
const char* TypeName(const int64_t*) { return "int"; }
const char* TypeName(const double*) { return "number"; }
const char* TypeName(const std::string*) { return "text"; }
const char* TypeName(const std::vector<std::string>*) { return "text..."; }
const char* TypeName(const std::vector<int>*) { return "int..."; }
const char* TypeName(const std::vector<double>*) { return "number..."; }

}  // namespace internal

OptionSet::OptionSet() {
  Add<std::string>("config", &config_path_,
                   "INI file with dotted keys ([section] key = value); the command line wins.",
                   "", Effect::kRuntime);
}

OptionSet::~OptionSet() = default;

namespace {

// Whether a flag or key of any of `options` is `name`.
bool NameTaken(const std::vector<std::unique_ptr<OptionSet::Option>>& options, const std::string& name) {
  for (const auto& other : options)
    if (other->flag == name || other->key == name || other->old_flag == name) return true;
  return false;
}

}  // namespace

void OptionSet::AddOption(std::unique_ptr<Option> option) {
  for (const auto& other : options_) HF_CHECK(other->key != option->key);
  // Taken: the option stays reachable by its dotted key.
  if (!option->flag.empty() && NameTaken(options_, option->flag)) option->flag.clear();
  if (option->flag == option->key) option->flag.clear();
  options_.push_back(std::move(option));
}

void OptionSet::AddOldFlag(const std::string& key, const std::string& old_flag) {
  if (NameTaken(options_, old_flag)) return;
  for (const auto& option : options_)
    if (option->key == key) option->old_flag = old_flag;
}

void OptionSet::AddPositional(const std::string& name, std::string* value,
                              const std::string& help) {
  positionals_.emplace_back(name, value);
  positional_help_.push_back(help);
}

namespace {

// An option key's section: its text before the first dot ("" for none).
std::string SectionOf(const std::string& key) {
  const auto dot = key.find('.');
  return dot == std::string::npos ? "" : key.substr(0, dot);
}

po::value_semantic* MakeSemantic(const OptionSet::Option& option) {
  if (option.is_list) return po::value<std::vector<std::string>>()->multitoken()->composing();
  if (option.is_bool) return po::value<std::string>()->implicit_value("true");
  return po::value<std::string>();
}

std::vector<std::string> Tokens(const po::variable_value& value) {
  if (const auto* list = boost::any_cast<std::vector<std::string>>(&value.value())) return *list;
  return {boost::any_cast<std::string>(value.value())};
}

}  // namespace

namespace {

// The keys of the config file `path` that `options` know, into `values`;
// the others' names into `unknown`.
Status ReadConfigFile(const std::string& path, const std::vector<std::unique_ptr<OptionSet::Option>>& options,
                      po::variables_map* values, std::vector<std::string>* unknown) {
  std::ifstream in(path);
  if (!in) return Status::InvalidArgument("cannot read config file " + path);
  po::options_description file_keys;
  for (const auto& option : options) {
    if (option->key == "config") continue;
    file_keys.add_options()(option->key.c_str(), option->is_list
                                                     ? po::value<std::vector<std::string>>()->composing()
                                                     : static_cast<po::value_semantic*>(po::value<std::string>()));
  }
  try {
    const auto parsed = po::parse_config_file(in, file_keys, /*allow_unregistered=*/true);
    po::store(parsed, *values);
    unknown->clear();
    for (const auto& o : parsed.options)
      if (o.unregistered) unknown->push_back(o.string_key);
  } catch (const po::error& e) {
    return Status::InvalidArgument("config file " + path + ": " + e.what());
  }
  return Status::Ok();
}

}  // namespace

Status OptionSet::Parse(const std::vector<std::string>& args) {
  po::options_description cli;
  cli.add_options()("help,h", "show this help");
  for (const auto& option : options_) {
    cli.add_options()(option->key.c_str(), MakeSemantic(*option));
    if (!option->flag.empty()) cli.add_options()(option->flag.c_str(), MakeSemantic(*option));
    if (!option->old_flag.empty()) cli.add_options()(option->old_flag.c_str(), MakeSemantic(*option));
  }
  po::positional_options_description positional;
  const std::string kPositionalKey = "__positional";
  cli.add_options()(kPositionalKey.c_str(), po::value<std::vector<std::string>>());
  positional.add(kPositionalKey.c_str(), -1);

  po::variables_map given;
  try {
    po::store(po::command_line_parser(args)
                  .options(cli)
                  .positional(positional)
                  .style(po::command_line_style::unix_style ^
                         po::command_line_style::allow_guessing)
                  .run(),
              given);
  } catch (const po::error& e) {
    return Status::InvalidArgument(e.what());
  }
  help_requested_ = given.count("help") > 0;
  given_.clear();
  deprecation_notes_.clear();
  if (help_requested_) return Status::Ok();

  // Positional arguments.
  std::vector<std::string> rest;
  if (given.count(kPositionalKey)) rest = given[kPositionalKey].as<std::vector<std::string>>();
  if (rest.size() > positionals_.size())
    return Status::InvalidArgument("unexpected argument '" + rest[positionals_.size()] + "'");
  for (size_t i = 0; i < rest.size(); ++i) *positionals_[i].second = rest[i];

  // The config file, if any, is read first so the command line can override it.
  auto find = [&](const Option& option) -> const po::variable_value* {
    if (!option.flag.empty() && given.count(option.flag)) return &given[option.flag];
    if (given.count(option.key)) return &given[option.key];
    if (!option.old_flag.empty() && given.count(option.old_flag)) {
      deprecation_notes_.push_back("--" + option.old_flag + " is the old name of --" +
                                   (option.flag.empty() ? option.key : option.flag) +
                                   "; it still works, but use the new name");
      return &given[option.old_flag];
    }
    return nullptr;
  };
  for (const auto& option : options_) {
    if (option->key != "config") continue;
    if (const auto* value = find(*option)) HF_RETURN_IF_ERROR(option->set(Tokens(*value)));
  }
  po::variables_map from_file;
  if (!config_path_.empty()) HF_RETURN_IF_ERROR(ReadConfigFile(config_path_, options_, &from_file, &unknown_config_keys_));

  for (const auto& option : options_) {
    if (option->key == "config") continue;
    const po::variable_value* value = find(*option);
    std::string origin = "command line";
    if (!value && from_file.count(option->key)) {
      value = &from_file[option->key];
      origin = "config file " + config_path_;
    }
    if (!value) continue;
    Status status = option->set(Tokens(*value));
    if (!status.ok())
      return Status::InvalidArgument("option --" + option->key + " (" + origin +
                                     "): " + status.message());
    given_.insert(option->key);
  }
  return Status::Ok();
}

Status OptionSet::ApplyConfigBeneath(const std::string& path) {
  po::variables_map from_file;
  std::vector<std::string> unknown;
  HF_RETURN_IF_ERROR(ReadConfigFile(path, options_, &from_file, &unknown));
  for (const auto& option : options_) {
    if (option->key == "config" || given_.count(option->key) || !from_file.count(option->key)) continue;
    if (Status status = option->set(Tokens(from_file[option->key])); !status.ok())
      return Status::InvalidArgument("option --" + option->key + " (config file " + path + "): " + status.message());
    given_.insert(option->key);
  }
  return Status::Ok();
}

bool OptionSet::WasGiven(const std::string& key) const { return given_.count(key) > 0; }

std::optional<std::vector<std::string>> OptionSet::Value(const std::string& key) const {
  for (const auto& option : options_)
    if (option->key == key) return option->get();
  return std::nullopt;
}

std::string OptionSet::Help(const std::string& usage, const std::string& description) const {
  std::ostringstream out;
  out << "Usage: " << usage << "\n\n" << description << "\n";
  if (!positionals_.empty()) {
    out << "\nArguments:\n";
    for (size_t i = 0; i < positionals_.size(); ++i)
      out << "  " << positionals_[i].first << "\n      " << positional_help_[i] << "\n";
  }
  // Grouped by section (the key's text before its first dot): those without
  // one first, then in the order they first appear, under a heading each when
  // there are several (run's options of every stage).
  std::vector<std::string> sections;
  for (const auto& option : options_) {
    const std::string section = SectionOf(option->key);
    if (std::find(sections.begin(), sections.end(), section) == sections.end()) sections.push_back(section);
  }
  std::stable_partition(sections.begin(), sections.end(), [](const std::string& s) { return s.empty(); });
  out << "\nOptions (each also accepted as 'key = value' under its [section] in --config):\n";
  for (const std::string& section : sections) {
    if (sections.size() > 1) out << "\n" << (section.empty() ? std::string("General") : section) << " options:\n";
    for (const auto& option : options_) {
      if (SectionOf(option->key) != section) continue;
      out << "  ";
      if (!option->flag.empty()) out << "--" << option->flag << ", ";
      out << "--" << option->key << " <" << option->type_name << ">";
      if (option->is_bool) out << " (--flag alone means true; --flag=false)";
      if (!option->old_flag.empty()) out << " (formerly --" << option->old_flag << ")";
      out << "\n      " << option->help;
      out << "\n      default: " << (option->default_text.empty() ? "(none)" : option->default_text) << "\n";
    }
    if (section.empty()) out << "  -h, --help\n      Show this help.\n";
  }
  return out.str();
}

std::string OptionSet::ToIni(const std::string& section, bool semantic_only) const {
  // Group by section (the text before the first dot), keeping registration order.
  std::vector<std::string> order;
  std::map<std::string, std::vector<std::string>> lines;
  for (const auto& option : options_) {
    if (option->key == "config") continue;
    if (semantic_only && option->effect != Effect::kSemantic) continue;
    const std::string group = SectionOf(option->key);
    const std::string name = group.empty() ? option->key : option->key.substr(group.size() + 1);
    if (!section.empty() && group != section) continue;
    if (!lines.count(group)) order.push_back(group);
    auto& group_lines = lines[group];
    const auto tokens = option->get();
    if (option->is_list) {
      if (tokens.empty()) group_lines.push_back("# " + name + " =");
      for (const auto& token : tokens) group_lines.push_back(name + " = " + token);
    } else {
      group_lines.push_back(name + " = " + (tokens.empty() ? "" : tokens[0]));
    }
  }
  std::ostringstream out;
  // Keys without a section come first: INI has no way back to the top level.
  std::stable_partition(order.begin(), order.end(), [](const std::string& g) { return g.empty(); });
  for (const auto& group : order) {
    if (!group.empty()) out << "[" << group << "]\n";
    for (const auto& line : lines[group]) out << line << "\n";
  }
  return out.str();
}

}  // namespace headforge
