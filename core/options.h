// Command-line and config-file options with one set of dotted keys.
//
// A stage's options live in a plain struct (with Check()); an OptionSet binds
// its fields to keys such as "ingest.fps". Every key is accepted on the command
// line as --ingest.fps and in an INI file given with --config as
//   [ingest]
//   fps = 5
// Most options also get a short flag (--fps) when no other option in the same
// command took it. Command line beats config file beats the struct's default.
#pragma once

#include <functional>
#include <memory>
#include <optional>
#include <set>
#include <cstdint>
#include <string>
#include <vector>

#include "core/status.h"

namespace headforge {

// A text-list option's tokens with comma-separated items split: {"a,b", "c"}
// -> {"a", "b", "c"} (number lists are split so when parsed; text lists keep
// their tokens whole, as a path may hold a comma).
std::vector<std::string> SplitCommaList(const std::vector<std::string>& tokens);

// Frames named by `tokens` out of `count` (numbered 0 to count - 1), in the
// order given: "all", N, A-B (both included) and A-B:S (every S-th from A),
// comma-separated or as separate tokens. InvalidArgument, naming the item,
// for text that is none of these or a frame outside the range.
Status ParseFrameList(const std::vector<std::string>& tokens, int count, std::vector<int>* frames);

class OptionSet {
 public:
  // Options that change a stage's outputs enter its fingerprint; the others
  // (threads, progress, paths of the workspace itself) do not.
  enum class Effect { kSemantic, kRuntime };

  OptionSet();
  ~OptionSet();
  OptionSet(const OptionSet&) = delete;
  OptionSet& operator=(const OptionSet&) = delete;

  // Binds `*value` to `key`; its current value is the default. `flag` is the
  // short command-line name ("" for none). Supported T: bool, int, int64_t,
  // double, std::string, std::vector<std::string>, std::vector<int>,
  // std::vector<double>. Lists take several tokens on the command line
  // (--video a.mp4 b.mp4), repeated lines or commas in a config file.
  template <typename T>
  void Add(const std::string& key, T* value, const std::string& help,
           const std::string& flag = "", Effect effect = Effect::kSemantic);

  // An earlier flag name of the option `key` (added before), still accepted
  // but named in deprecation_notes() with the present one when used. Not
  // kept where another option of this command owns the name.
  void AddOldFlag(const std::string& key, const std::string& old_flag);

  // A positional argument (e.g. WORKSPACE for `status`), stored as text.
  void AddPositional(const std::string& name, std::string* value, const std::string& help);

  // Parses the arguments that follow the command name, reading --config FILE
  // when given. InvalidArgument on an unknown option or a value of the wrong type.
  Status Parse(const std::vector<std::string>& args);

  // After Parse: the options nobody gave take their values from the config
  // file `path` (the command line and --config still win), and count as
  // given. `headforge run` without --video reads ingest's recorded options so.
  Status ApplyConfigBeneath(const std::string& path);

  bool help_requested() const { return help_requested_; }
  // Whether the last Parse set `key` from the command line or the config
  // file (presets fill only the options nobody gave).
  bool WasGiven(const std::string& key) const;
  // The current value of `key` as tokens (a stage reading another stage's
  // option in `headforge run`); nullopt when no option has that key.
  std::optional<std::vector<std::string>> Value(const std::string& key) const;
  // Keys given in a config file that no option of this command knows.
  const std::vector<std::string>& unknown_config_keys() const { return unknown_config_keys_; }
  // After Parse: one line for each old flag name the command line used,
  // naming the present one.
  const std::vector<std::string>& deprecation_notes() const { return deprecation_notes_; }

  // The option table for `headforge <command> --help`.
  std::string Help(const std::string& usage, const std::string& description) const;

  // Effective values as INI text; `section` ("ingest") keeps only that section's
  // keys; `semantic_only` drops the runtime ones. Stable order: registration.
  std::string ToIni(const std::string& section = "", bool semantic_only = false) const;

  struct Option;

 private:
  void AddOption(std::unique_ptr<Option> option);

  std::vector<std::unique_ptr<Option>> options_;
  std::vector<std::pair<std::string, std::string*>> positionals_;
  std::vector<std::string> positional_help_;
  std::string config_path_;
  bool help_requested_ = false;
  std::vector<std::string> unknown_config_keys_;
  std::vector<std::string> deprecation_notes_;
  std::set<std::string> given_;
};

// Internal: the type-erased option record behind Add<T>().
struct OptionSet::Option {
  std::string key;
  std::string flag;
  std::string old_flag;  // an earlier name, accepted with a note ("" for none)
  std::string help;
  std::string type_name;
  std::string default_text;
  bool is_list = false;
  bool is_bool = false;
  Effect effect = Effect::kSemantic;
  // Parses tokens into the bound field.
  std::function<Status(const std::vector<std::string>&)> set;
  // Current value as tokens.
  std::function<std::vector<std::string>()> get;
};

namespace internal {
// Conversions between tokens and the supported field types (options.cc).
#define HF_OPTION_TYPE(T)                                            \
  Status ParseTokens(const std::vector<std::string>& tokens, T* value); \
  std::vector<std::string> FormatTokens(const T& value);              \
  const char* TypeName(const T*);
HF_OPTION_TYPE(bool)
HF_OPTION_TYPE(int)
HF_OPTION_TYPE(int64_t)
HF_OPTION_TYPE(double)
HF_OPTION_TYPE(std::string)
HF_OPTION_TYPE(std::vector<std::string>)
HF_OPTION_TYPE(std::vector<int>)
HF_OPTION_TYPE(std::vector<double>)
#undef HF_OPTION_TYPE
template <typename T>
constexpr bool kIsList = false;
template <typename E>
constexpr bool kIsList<std::vector<E>> = true;
}  // namespace internal

template <typename T>
void OptionSet::Add(const std::string& key, T* value, const std::string& help,
                    const std::string& flag, Effect effect) {
  auto option = std::make_unique<Option>();
  option->key = key;
  option->flag = flag;
  option->help = help;
  option->type_name = internal::TypeName(static_cast<const T*>(nullptr));
  option->is_list = internal::kIsList<T>;
  option->is_bool = std::is_same<T, bool>::value;
  option->effect = effect;
  option->set = [value](const std::vector<std::string>& tokens) {
    return internal::ParseTokens(tokens, value);
  };
  option->get = [value]() { return internal::FormatTokens(*value); };
  std::string joined;
  for (const auto& token : option->get()) joined += (joined.empty() ? "" : " ") + token;
  option->default_text = joined;
  AddOption(std::move(option));
}

}  // namespace headforge
