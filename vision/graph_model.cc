#include "vision/graph_model.h"

#include <torch/torch.h>

#include <algorithm>
#include <set>
#include <stdexcept>

#include <nlohmann/json.hpp>

#include "core/json_io.h"
#include "vision/tfjs_weights.h"

namespace headforge {

namespace {

std::string DecodeBase64(const std::string& in) {
  static const std::string kAlphabet = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  int bits = 0, value = 0;
  for (char c : in) {
    const size_t d = kAlphabet.find(c);
    if (d == std::string::npos) continue;  // padding and line breaks
    value = (value << 6) | int(d);
    bits += 6;
    if (bits >= 8) {
      bits -= 8;
      out.push_back(char((value >> bits) & 0xff));
    }
  }
  return out;
}

int64_t JsonInt(const nlohmann::json& v) {
  return v.is_string() ? std::stoll(v.get<std::string>()) : v.get<int64_t>();
}

GraphAttr ParseAttr(const nlohmann::json& value) {
  GraphAttr a;
  if (value.contains("list")) {
    a.is_list = true;
    const nlohmann::json& list = value["list"];
    if (list.contains("i"))
      for (const auto& v : list["i"]) a.ints.push_back(JsonInt(v));
    if (list.contains("f"))
      for (const auto& v : list["f"]) a.floats.push_back(v.get<double>());
    if (list.contains("s"))
      for (const auto& v : list["s"]) a.strings.push_back(DecodeBase64(v.get<std::string>()));
    return a;
  }
  if (value.contains("i")) a.ints.push_back(JsonInt(value["i"]));
  if (value.contains("f")) a.floats.push_back(value["f"].is_string() ? std::stod(value["f"].get<std::string>())
                                                                     : value["f"].get<double>());
  if (value.contains("b")) a.boolean = value["b"].get<bool>();
  if (value.contains("s")) a.strings.push_back(DecodeBase64(value["s"].get<std::string>()));
  if (value.contains("type")) a.type = value["type"].get<std::string>();
  return a;
}

// "name", "name:2" or "^name" split into the node's name and output index (-1 for control).
std::pair<std::string, int> SplitInput(const std::string& input) {
  if (!input.empty() && input[0] == '^') return {input.substr(1), -1};
  const size_t colon = input.rfind(':');
  if (colon != std::string::npos && colon + 1 < input.size() &&
      std::all_of(input.begin() + colon + 1, input.end(), ::isdigit))
    return {input.substr(0, colon), std::stoi(input.substr(colon + 1))};
  return {input, 0};
}

}  // namespace

int64_t GraphNode::Int(const std::string& key, int64_t fallback) const {
  const auto it = attrs.find(key);
  return it == attrs.end() || it->second.ints.empty() ? fallback : it->second.ints[0];
}
double GraphNode::Float(const std::string& key, double fallback) const {
  const auto it = attrs.find(key);
  return it == attrs.end() || it->second.floats.empty() ? fallback : it->second.floats[0];
}
bool GraphNode::Bool(const std::string& key, bool fallback) const {
  const auto it = attrs.find(key);
  return it == attrs.end() ? fallback : it->second.boolean;
}
std::string GraphNode::String(const std::string& key, const std::string& fallback) const {
  const auto it = attrs.find(key);
  return it == attrs.end() || it->second.strings.empty() ? fallback : it->second.strings[0];
}
std::vector<int64_t> GraphNode::Ints(const std::string& key) const {
  const auto it = attrs.find(key);
  return it == attrs.end() ? std::vector<int64_t>() : it->second.ints;
}
std::vector<std::string> GraphNode::Strings(const std::string& key) const {
  const auto it = attrs.find(key);
  return it == attrs.end() ? std::vector<std::string>() : it->second.strings;
}
std::string GraphNode::Type(const std::string& key, const std::string& fallback) const {
  const auto it = attrs.find(key);
  return it == attrs.end() || it->second.type.empty() ? fallback : it->second.type;
}

Status GraphModel::Load(const fs::path& model_json, GraphModel* model) {
  nlohmann::json json;
  const Status read = ReadJson(model_json, &json);
  if (!read.ok()) return read.WithContext("graph model");
  return FromJson(json, model_json.parent_path(), model).WithContext(model_json.string());
}

Status GraphModel::FromJson(const nlohmann::json& json, const fs::path& dir, GraphModel* model) {
  *model = GraphModel();
  try {
    if (!json.contains("modelTopology") || !json["modelTopology"].contains("node"))
      return Status::DataError("not a TensorFlow.js graph model (no modelTopology.node)");
    if (json["modelTopology"].contains("library") && json["modelTopology"]["library"].contains("function") &&
        !json["modelTopology"]["library"]["function"].empty())
      return Status::DataError("the graph calls functions of its library, which this runner does not run");
    const nlohmann::json& nodes = json["modelTopology"]["node"];
    for (const nlohmann::json& n : nodes) {
      GraphNode node;
      node.name = n.at("name").get<std::string>();
      node.op = n.at("op").get<std::string>();
      if (n.contains("attr"))
        for (const auto& [key, value] : n["attr"].items()) node.attrs[key] = ParseAttr(value);
      if (model->index_.count(node.name)) return Status::DataError("two nodes are named " + node.name);
      model->index_[node.name] = static_cast<int>(model->nodes_.size());
      model->nodes_.push_back(std::move(node));
    }
    // Inputs, once every node is named.
    for (size_t i = 0; i < nodes.size(); ++i) {
      if (!nodes[i].contains("input")) continue;
      for (const auto& input : nodes[i]["input"]) {
        const auto [name, output] = SplitInput(input.get<std::string>());
        if (output < 0) continue;
        const auto it = model->index_.find(name);
        if (it == model->index_.end())
          return Status::DataError("node " + model->nodes_[i].name + " reads " + name + ", which is not in the graph");
        model->nodes_[i].inputs.emplace_back(it->second, output);
      }
    }
    // Ops, refusing unknown ones now rather than at the first run.
    model->ops_.assign(model->nodes_.size(), nullptr);
    for (size_t i = 0; i < model->nodes_.size(); ++i) {
      const GraphNode& node = model->nodes_[i];
      if (node.op == "Const" || node.op == "Placeholder") continue;
      model->ops_[i] = FindGraphOp(node.op);
      if (!model->ops_[i])
        return Status::DataError("the graph has op " + node.op + " (node " + node.name +
                                 "), which this runner does not implement");
    }
    std::map<std::string, torch::Tensor> weights;
    if (json.contains("weightsManifest"))
      HF_RETURN_IF_ERROR(ReadTfjsWeightGroups(json["weightsManifest"], dir, "the graph model", &weights));
    for (size_t i = 0; i < model->nodes_.size(); ++i) {
      if (model->nodes_[i].op != "Const") continue;
      const auto it = weights.find(model->nodes_[i].name);
      if (it == weights.end())
        return Status::DataError("constant " + model->nodes_[i].name + " has no value in the weights");
      model->constants_[static_cast<int>(i)] = it->second;
    }
    if (json.contains("signature") && json["signature"].contains("outputs")) {
      for (const auto& [key, value] : json["signature"]["outputs"].items()) {
        const std::string name = value.value("name", key);
        model->signature_outputs_[key] = name;
        model->default_outputs_.push_back(key);
      }
    }
  } catch (const std::exception& e) {
    return Status::DataError(std::string("malformed graph model: ") + e.what());
  }
  if (model->default_outputs_.empty()) {
    std::set<int> read;
    for (const GraphNode& node : model->nodes_)
      for (const auto& [producer, k] : node.inputs) read.insert(producer);
    for (size_t i = 0; i < model->nodes_.size(); ++i)
      if (!read.count(static_cast<int>(i)) && model->nodes_[i].op != "Const" && model->nodes_[i].op != "NoOp")
        model->default_outputs_.push_back(model->nodes_[i].name);
  }
  for (const std::string& name : model->default_outputs_) {
    std::pair<int, int> resolved;
    HF_RETURN_IF_ERROR(model->Resolve(name, &resolved));
  }
  return Status::Ok();
}

Status GraphModel::Resolve(const std::string& name, std::pair<int, int>* output) const {
  const auto sig = signature_outputs_.find(name);
  const auto [node, k] = SplitInput(sig != signature_outputs_.end() ? sig->second : name);
  const auto it = index_.find(node);
  if (it == index_.end() || k < 0) return Status::InvalidArgument("the graph has no output " + name);
  *output = {it->second, k};
  return Status::Ok();
}

std::vector<std::string> GraphModel::InputNames() const {
  std::vector<std::string> names;
  for (const GraphNode& node : nodes_)
    if (node.op == "Placeholder") names.push_back(node.name);
  return names;
}

std::vector<std::string> GraphModel::OutputNames() const { return default_outputs_; }

void GraphModel::To(const torch::Device& device) {
  for (auto& [i, t] : constants_) t = t.to(device);
  device_ = device;
}

Status GraphModel::Run(const std::map<std::string, torch::Tensor>& inputs, const std::vector<std::string>& outputs,
                       std::vector<torch::Tensor>* results) const {
  const std::vector<std::string>& wanted = outputs.empty() ? default_outputs_ : outputs;
  std::vector<std::pair<int, int>> targets;
  for (const std::string& name : wanted) {
    std::pair<int, int> t;
    HF_RETURN_IF_ERROR(Resolve(name, &t));
    targets.push_back(t);
  }
  // The nodes the targets need, in dependency order (depth-first, iterative),
  // and how many of them read each node, to free tensors after their last use.
  const int n = static_cast<int>(nodes_.size());
  std::vector<int> order, state(n, 0);  // 0 unvisited, 1 on the stack, 2 done
  std::vector<int> readers(n, 0);
  for (const auto& [root, k] : targets) {
    std::vector<std::pair<int, size_t>> stack{{root, 0}};
    if (state[root] == 2) continue;
    state[root] = 1;
    while (!stack.empty()) {
      auto& [node, next] = stack.back();
      if (next < nodes_[node].inputs.size()) {
        const int in = nodes_[node].inputs[next++].first;
        if (state[in] == 1) return Status::DataError("the graph has a cycle through node " + nodes_[in].name);
        if (state[in] == 0) {
          state[in] = 1;
          stack.emplace_back(in, 0);
        }
        continue;
      }
      state[node] = 2;
      order.push_back(node);
      for (const auto& [in, k2] : nodes_[node].inputs) ++readers[in];
      stack.pop_back();
    }
  }
  for (const auto& [root, k] : targets) ++readers[root];

  // Values per node; an undefined tensor in a node's outputs is a dead output.
  std::vector<std::vector<torch::Tensor>> values(n);
  std::vector<bool> dead(n, false);
  torch::NoGradGuard no_grad;
  for (int i : order) {
    const GraphNode& node = nodes_[i];
    if (node.op == "Const") {
      values[i] = {constants_.at(i)};
      continue;
    }
    if (node.op == "Placeholder") {
      auto it = inputs.find(node.name);
      if (it == inputs.end()) it = inputs.find(node.name + ":0");
      if (it == inputs.end()) return Status::InvalidArgument("the graph needs input " + node.name);
      values[i] = {it->second.to(device_)};
      continue;
    }
    std::vector<torch::Tensor> args;
    bool any_dead = false;
    for (const auto& [in, k] : node.inputs) {
      const bool is_dead = dead[in] || k >= static_cast<int>(values[in].size()) || !values[in][k].defined();
      any_dead = any_dead || is_dead;
      args.push_back(is_dead ? torch::Tensor() : values[in][k]);
    }
    if (any_dead && node.op != "Merge") {
      dead[i] = true;
    } else {
      try {
        values[i] = (*ops_[i])(node, args);
      } catch (const std::exception& e) {
        return Status::DataError("node " + node.name + " (" + node.op + "): " + e.what());
      }
      dead[i] = values[i].empty();
    }
    for (const auto& [in, k] : node.inputs)
      if (--readers[in] == 0 && nodes_[in].op != "Const") values[in].clear();
  }
  results->clear();
  for (size_t t = 0; t < targets.size(); ++t) {
    const auto [node, k] = targets[t];
    if (dead[node] || k >= static_cast<int>(values[node].size()) || !values[node][k].defined())
      return Status::DataError("output " + wanted[t] + " was not computed (a branch of the graph not taken)");
    results->push_back(values[node][k]);
  }
  return Status::Ok();
}

}  // namespace headforge
