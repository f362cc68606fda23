// A batch manifest: one capture per row, for `headforge batch submit`.
//
// A manifest is data, never code: a text file of tab-separated rows
//   name <TAB> preset <TAB> config <TAB> input [<TAB> input ...]
// where `name` is the capture's workspace folder under the batch root,
// `preset` a training preset (empty: the default), `config` an INI-style
// option file (empty or "-": none) and each input a video or an image folder,
// one per camera. Relative paths are relative to the manifest's folder.
// Blank lines and lines starting with '#' are skipped. Nothing in a field is
// ever read by a shell: each reaches headforge as one argument.
#pragma once

#include <string>
#include <vector>

#include "core/fs.h"
#include "core/status.h"

namespace headforge {

struct BatchRow {
  int line = 0;                     // 1-based line in the manifest, for messages
  std::string name;                 // the workspace folder's name under the root
  std::string preset;               // empty: the training stage's default
  std::string config;               // absolute path of an option file, or empty
  std::vector<std::string> inputs;  // absolute paths, one per camera
};

// Why `name` cannot name a capture's folder ("" when it can): empty, "." or
// "..", a '/', a leading '.' or '-', or a control character (tab, newline).
std::string BadCaptureName(const std::string& name);

// Parses manifest text whose relative paths are relative to `base`. Every
// bad row (too few fields, bad or duplicate name, unknown preset, an input
// or config that does not exist) is named in one InvalidArgument status,
// "<source> line <n> (<name>): <why>" per row; nothing is returned then.
Status ParseManifest(const std::string& text, const fs::path& base, const std::string& source,
                     const std::vector<std::string>& presets, std::vector<BatchRow>* rows);
// ParseManifest of a file.
Status ReadManifest(const fs::path& manifest, const std::vector<std::string>& presets, std::vector<BatchRow>* rows);

}  // namespace headforge
