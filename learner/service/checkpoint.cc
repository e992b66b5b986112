#include "learner/service/checkpoint.h"

#include <dirent.h>
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <sstream>
#include <stdexcept>

namespace perch {
namespace {

constexpr char kMagic[8] = {'P', 'E', 'R', 'C', 'H', 'C', 'K', 'P'};
constexpr size_t kHeaderSize = 8 + 4 + 8 + 4;

void PutLe(std::string* s, uint64_t v, int bytes) {
  for (int i = 0; i < bytes; ++i) s->push_back(static_cast<char>((v >> (8 * i)) & 0xff));
}
uint64_t GetLe(const std::string& s, size_t off, int bytes) {
  uint64_t v = 0;
  for (int i = 0; i < bytes; ++i) v |= uint64_t{static_cast<unsigned char>(s[off + i])} << (8 * i);
  return v;
}

void MakeDirs(const std::string& path) {
  std::string cur;
  std::stringstream ss(path);
  std::string part;
  if (!path.empty() && path[0] == '/') cur = "/";
  while (std::getline(ss, part, '/')) {
    if (part.empty()) continue;
    cur += part + "/";
    if (::mkdir(cur.c_str(), 0755) != 0 && errno != EEXIST) {
      throw std::runtime_error(cur + ": cannot create directory: " + std::strerror(errno));
    }
  }
}

}  // namespace

std::string FrameCheckpoint(const proto::Checkpoint& ckpt) {
  std::string payload;
  if (!ckpt.SerializeToString(&payload)) throw std::runtime_error("checkpoint: serialize failed");
  std::string out(kMagic, sizeof(kMagic));
  PutLe(&out, kCheckpointFormat, 4);
  PutLe(&out, payload.size(), 8);
  PutLe(&out, Crc32(payload.data(), payload.size()), 4);
  out += payload;
  return out;
}

proto::Checkpoint ReadCheckpointFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw CheckpointError(path + ": cannot open checkpoint");
  std::stringstream ss;
  ss << in.rdbuf();
  const std::string data = ss.str();
  if (data.size() < kHeaderSize || std::memcmp(data.data(), kMagic, sizeof(kMagic)) != 0) {
    throw CheckpointError(path + ": not a Perch checkpoint (bad magic or shorter than header)");
  }
  const uint32_t format = static_cast<uint32_t>(GetLe(data, 8, 4));
  if (format != kCheckpointFormat) {
    throw CheckpointError(path + ": checkpoint format " + std::to_string(format) +
                          ", this build reads format " + std::to_string(kCheckpointFormat));
  }
  const uint64_t len = GetLe(data, 12, 8);
  if (len != data.size() - kHeaderSize) {
    throw CheckpointError(path + ": truncated or padded: header says " + std::to_string(len) +
                          " payload bytes, file has " + std::to_string(data.size() - kHeaderSize));
  }
  const uint32_t crc = static_cast<uint32_t>(GetLe(data, 20, 4));
  if (Crc32(data.data() + kHeaderSize, len) != crc) {
    throw CheckpointError(path + ": CRC mismatch (corrupt checkpoint)");
  }
  proto::Checkpoint ckpt;
  if (!ckpt.ParseFromArray(data.data() + kHeaderSize, static_cast<int>(len))) {
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
  MakeDirs(dir_);
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
