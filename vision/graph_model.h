// A runner of TensorFlow.js graph models (model.json with its weight shards,
// the format of tfjs-converter's "graph-model") in LibTorch: the graph's nodes
// are read once, the weights become tensors, and each run evaluates, in
// dependency order, the nodes the asked outputs need.
//
// Tensors keep the graph's own layouts (NHWC images, TensorFlow's filter
// layouts); convolutions and pools reorder to LibTorch's and back. TensorFlow's
// dataflow control (Switch, Merge) is followed: a Switch's untaken output is
// "dead", and so is every node fed by a dead input except a Merge, which passes
// on its live one. A graph with an op this runner does not know fails at load,
// naming the op and its node.
//
// This header includes LibTorch: it is for vision/ and its tests. Stages reach
// the models through vision/face_mesh.h and vision/person_matte.h.
#pragma once

#include <torch/types.h>

#include <functional>
#include <map>
#include <string>
#include <vector>

#include <nlohmann/json_fwd.hpp>

#include "core/fs.h"
#include "core/status.h"

namespace headforge {

// A node attribute's value as the graph stores it (TensorFlow's AttrValue in
// JSON): integers, floats, booleans, strings (base64 in the file, decoded
// here), types and lists of them.
struct GraphAttr {
  std::vector<int64_t> ints;
  std::vector<double> floats;
  std::vector<std::string> strings;
  bool boolean = false;
  std::string type;  // "DT_FLOAT", ...
  bool is_list = false;
};

struct GraphNode {
  std::string name, op;
  // (producer node, its output index) per data input; control inputs ("^x") dropped.
  std::vector<std::pair<int, int>> inputs;
  std::map<std::string, GraphAttr> attrs;

  int64_t Int(const std::string& key, int64_t fallback) const;
  double Float(const std::string& key, double fallback) const;
  bool Bool(const std::string& key, bool fallback) const;
  std::string String(const std::string& key, const std::string& fallback) const;
  std::vector<int64_t> Ints(const std::string& key) const;
  std::vector<std::string> Strings(const std::string& key) const;
  std::string Type(const std::string& key, const std::string& fallback) const;
};

// An op: the node and its input tensors in, its outputs out. Throws
// std::runtime_error (caught by the runner, which names the node) on inputs
// it cannot take.
using GraphOp = std::function<std::vector<torch::Tensor>(const GraphNode&, const std::vector<torch::Tensor>&)>;
// The op of that name, or nullptr.
const GraphOp* FindGraphOp(const std::string& op);
// Every op name the runner knows, sorted.
std::vector<std::string> KnownGraphOps();

class GraphModel {
 public:
  // Reads model.json and its shards. DataError names the file and what is
  // wrong; an unknown op is a DataError naming it and its node.
  static Status Load(const fs::path& model_json, GraphModel* model);
  // The same from the JSON already read; shards are found beside `dir`.
  static Status FromJson(const nlohmann::json& json, const fs::path& dir, GraphModel* model);

  // Runs the graph. `inputs` by placeholder name (a ":0" suffix is allowed);
  // `outputs` by the signature's output key or a node's name, with ":k" for
  // its k-th output; empty: the signature's outputs (else the nodes nothing
  // reads). Placeholders a run needs but is not given are an InvalidArgument.
  Status Run(const std::map<std::string, torch::Tensor>& inputs, const std::vector<std::string>& outputs,
             std::vector<torch::Tensor>* results) const;

  // Moves the weights (and runs) to `device`.
  void To(const torch::Device& device);
  torch::Device device() const { return device_; }

  std::vector<std::string> InputNames() const;   // the placeholders
  std::vector<std::string> OutputNames() const;  // what an empty `outputs` runs
  const std::vector<GraphNode>& nodes() const { return nodes_; }

 private:
  Status Resolve(const std::string& name, std::pair<int, int>* output) const;

  std::vector<GraphNode> nodes_;
  std::vector<const GraphOp*> ops_;             // per node; nullptr for Const and Placeholder
  std::map<std::string, int> index_;            // node name -> index
  std::map<int, torch::Tensor> constants_;      // Const nodes' values
  std::map<std::string, std::string> signature_outputs_;  // key -> "node:k"
  std::vector<std::string> default_outputs_;
  torch::Device device_ = torch::kCPU;
};

}  // namespace headforge
