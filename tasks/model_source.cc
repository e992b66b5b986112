#include "tasks/model_source.h"

#include <cstring>
#include <filesystem>

#include "common/file_util.h"
#include "common/proto/wire.pb.h"
#include "common/subtasks.h"
#include "tasks/state_bank.h"

namespace perch {
namespace {

// A parsed ModelWeights that is self-consistent (a shape and as many params as it says).
bool Plausible(const proto::ModelWeights& w) {
  return w.has_shape() && !w.shape().kind().empty() && w.shape().obs_dim() > 0 &&
         w.params_size() > 0 && w.params_size() == w.shape().num_params();
}

std::string ReadAll(const std::string& path) {
  std::string bytes = ReadFileBytes(path, "model file");
  if (bytes.empty()) throw ConfigError(path + ": empty model file");
  return bytes;
}

// A "PERCHCKP" frame's payload, checked (length, CRC-32) and parsed; ConfigError naming the file.
proto::Checkpoint ParseCheckpoint(const std::string& path, const std::string& bytes) {
  const std::string payload =
      UnframePayload(bytes, path, kCheckpointMagic, kCheckpointFormat, "checkpoint");
  proto::Checkpoint ck;
  if (!ck.ParseFromString(payload)) throw ConfigError(path + ": checkpoint payload does not parse");
  return ck;
}

}  // namespace

// The experiment config saved with a model: a checkpoint's resolved config, or a run dir's
// config.json. Null when the file carries none (a bare ModelWeights).
Json SavedConfig(const std::string& model_path) {
  namespace fs = std::filesystem;
  if (fs::is_directory(model_path)) {
    const fs::path cfg = fs::path(model_path) / "config.json";
    return fs::exists(cfg) ? LoadJsonFile(cfg.string()) : Json();
  }
  const std::string bytes = ReadAll(model_path);
  if (!HasCheckpointMagic(bytes)) return Json();
  const proto::Checkpoint c = ParseCheckpoint(model_path, bytes);
  if (c.resolved_config_json().empty()) return Json();
  try {
    return Json::parse(c.resolved_config_json());
  } catch (const std::exception& e) {
    throw ConfigError(model_path + ": saved config does not parse: " + e.what());
  }
}

// A run dir's newest checkpoint; any other path as given.
std::string ModelFile(const std::string& model_path) {
  namespace fs = std::filesystem;
  if (!fs::is_directory(model_path)) return model_path;
  std::string newest;
  const fs::path dir = fs::path(model_path) / "checkpoints";
  if (fs::is_directory(dir)) {
    for (const auto& e : fs::directory_iterator(dir)) {
      const std::string n = e.path().filename().string();
      if (n.rfind("ckpt-", 0) == 0 && n.size() > 4 && n.substr(n.size() - 4) == ".bin" &&
          (newest.empty() || n > fs::path(newest).filename().string())) {
        newest = e.path().string();
      }
    }
  }
  if (newest.empty())
    throw ConfigError(model_path + ": a directory without checkpoints/ckpt-*.bin");
  return newest;
}

proto::ModelWeights LoadModelFile(const std::string& path) {
  const std::string bytes = ReadAll(path);
  if (HasCheckpointMagic(bytes)) {
    const proto::Checkpoint ck = ParseCheckpoint(path, bytes);
    if (!ck.has_trainer() || !Plausible(ck.trainer().model())) {
      throw ConfigError(path + ": checkpoint holds no usable trainer.model");
    }
    return ck.trainer().model();
  }
  // Protobuf parsing is lenient, so accept a message only when it is self-consistent.
  proto::LearnerState state;
  if (state.ParseFromString(bytes) && state.has_model() && Plausible(state.model())) {
    return state.model();
  }
  proto::ModelWeights w;
  if (w.ParseFromString(bytes) && Plausible(w)) return w;
  throw ConfigError(path +
                    ": not a perch.proto.ModelWeights, LearnerState or PERCHCKP checkpoint (" +
                    std::to_string(bytes.size()) + " bytes; corrupt or another format)");
}

FrozenPolicyData LoadFrozenPolicy(const std::string& name, const std::string& model_path) {
  FrozenPolicyData p;
  p.name = name;
  const std::string file = ModelFile(model_path);
  p.model = LoadModelFile(file).SerializeAsString();
  const Json saved = SavedConfig(model_path);
  if (!saved.is_null()) p.saved_config = saved.dump();
  p.source = file + " (sha256 " + FileSha256(file) + ")";
  return p;
}

std::vector<FrozenPolicyData> FrozenPoliciesIn(const std::string& model_path) {
  const std::string file = ModelFile(model_path);
  const std::string bytes = ReadAll(file);
  if (!HasCheckpointMagic(bytes)) return {};
  const proto::Checkpoint c = ParseCheckpoint(file, bytes);
  std::vector<FrozenPolicyData> out;
  for (const proto::TaskPolicy& p : c.weights().policies()) {
    if (!p.frozen()) continue;
    const int id = SubtaskIdOfWire(p.task());
    if (id < 0) throw ConfigError(file + ": a frozen policy of an unknown subtask");
    out.push_back(
        {SubtaskName(id), p.model().SerializeAsString(), p.saved_config_json(), p.source()});
  }
  return out;
}

}  // namespace perch
