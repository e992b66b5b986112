#include "learner/service/checkpoint.h"

#include <dirent.h>
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <stdexcept>

#include "common/json_util.h"  // ConfigError

namespace perch {
std::string FrameCheckpoint(const proto::Checkpoint& ckpt) {
  std::string payload;
  if (!ckpt.SerializeToString(&payload)) throw std::runtime_error("checkpoint: serialize failed");
  return FramePayload(kCheckpointMagic, kCheckpointFormat, payload);
}

proto::Checkpoint ReadCheckpointFile(const std::string& path) {
  // The shared reader and frame check (common/file_util.h); their ConfigError becomes a
  // CheckpointError, which the store's fallback to an older checkpoint catches.
  std::string payload;
  try {
    payload = UnframePayload(ReadFileBytes(path, "checkpoint"), path, kCheckpointMagic,
                             kCheckpointFormat, "checkpoint");
  } catch (const ConfigError& e) {
    throw CheckpointError(e.what());
  }
  proto::Checkpoint ckpt;
  if (!ckpt.ParseFromString(payload)) {
    throw CheckpointError(path + ": payload does not parse as perch.proto.Checkpoint");
  }
  if (ckpt.wire_version() != proto::WIRE_VERSION_CURRENT) {
    throw CheckpointError(path + ": wire version " + std::to_string(ckpt.wire_version()) +
                          ", expected " + std::to_string(proto::WIRE_VERSION_CURRENT));
  }
  return ckpt;
}

CheckpointStore::CheckpointStore(std::string run_dir, int keep_last, int milestone_every)
    : dir_(std::move(run_dir) + "/checkpoints"),
      keep_last_(std::max(1, keep_last)),
      milestone_every_(milestone_every) {}

std::string CheckpointStore::PathFor(uint64_t update) const {
  char name[64];
  std::snprintf(name, sizeof(name), "/ckpt-%010llu.bin", static_cast<unsigned long long>(update));
  return dir_ + name;
}

std::vector<uint64_t> CheckpointStore::List() const {
  std::vector<uint64_t> out;
  DIR* d = ::opendir(dir_.c_str());
  if (d == nullptr) return out;
  while (dirent* e = ::readdir(d)) {
    // Exactly ckpt-<10 digits>.bin; .tmp leftovers of an interrupted write are ignored.
    const std::string name = e->d_name;
    if (name.size() != 19 || name.compare(0, 5, "ckpt-") != 0 || name.compare(15, 4, ".bin") != 0) {
      continue;
    }
    const std::string digits = name.substr(5, 10);
    if (digits.find_first_not_of("0123456789") != std::string::npos) continue;
    out.push_back(std::stoull(digits));
  }
  ::closedir(d);
  std::sort(out.begin(), out.end());
  return out;
}

std::string CheckpointStore::Save(const proto::Checkpoint& ckpt) {
  std::error_code ec;
  std::filesystem::create_directories(dir_, ec);
  if (ec) throw std::runtime_error(dir_ + ": cannot create directory: " + ec.message());
  const uint64_t update = ckpt.counters().updates();
  const std::string path = PathFor(update);
  WriteFileAtomic(path, FrameCheckpoint(ckpt));
  std::vector<uint64_t> all = List();
  int kept = 0;
  for (auto it = all.rbegin(); it != all.rend(); ++it) {
    const bool milestone = milestone_every_ > 0 && *it % milestone_every_ == 0 && *it > 0;
    if (*it == update || kept < keep_last_) {
      ++kept;
      continue;
    }
    if (!milestone) ::unlink(PathFor(*it).c_str());
  }
  return path;
}

bool CheckpointStore::LoadLatestGood(const std::function<void(const proto::Checkpoint&)>& accept,
                                     const std::function<void(const std::string&)>& warn,
                                     proto::Checkpoint* out, std::string* path_out,
                                     std::vector<std::string>* errors) const {
  std::vector<uint64_t> all = List();
  for (auto it = all.rbegin(); it != all.rend(); ++it) {
    const std::string path = PathFor(*it);
    try {
      proto::Checkpoint c = ReadCheckpointFile(path);
      if (c.counters().updates() != *it) {
        throw CheckpointError(path + ": holds update " + std::to_string(c.counters().updates()) +
                              " but is named for update " + std::to_string(*it));
      }
      accept(c);
      *out = std::move(c);
      if (path_out) *path_out = path;
      return true;
    } catch (const CheckpointError& e) {
      if (errors) errors->push_back(e.what());
      if (warn) warn(std::string("refusing checkpoint: ") + e.what());
    }
  }
  return false;
}

}  // namespace perch
