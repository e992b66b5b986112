// Checkpoint files of a run: <run_dir>/checkpoints/ckpt-<update, 10 digits>.bin. Each is written
// atomically (temporary file, fsync, rename, fsync of the directory) and framed so that a torn or
// corrupted file is detected:
//   "PERCHCKP" (8 bytes) | format u32 LE | payload length u64 LE | CRC-32 of payload u32 LE |
//   payload
// The payload is a serialised perch.proto.Checkpoint.
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "common/file_util.h"  // kCheckpointMagic/Format, FramePayload, WriteFileAtomic
#include "common/proto/wire.pb.h"

namespace perch {

// Frame/unframe (the shared frame of common/file_util.h). ReadCheckpointFile throws
// CheckpointError naming the file and the problem (unreadable, not a checkpoint, another format,
// truncated, CRC mismatch, another wire version).
std::string FrameCheckpoint(const proto::Checkpoint& ckpt);

class CheckpointError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};
proto::Checkpoint ReadCheckpointFile(const std::string& path);

// Rotation: keeps the newest `keep_last` files plus every update that is a multiple of
// `milestone_every` (0: no milestones).
class CheckpointStore {
 public:
  CheckpointStore(std::string run_dir, int keep_last, int milestone_every);

  std::string dir() const { return dir_; }
  std::string PathFor(uint64_t update) const;
  // Update numbers of the files present, ascending.
  std::vector<uint64_t> List() const;
  // Writes ckpt (named by ckpt.counters().updates), then deletes rotated-out files. Returns the
  // path.
  std::string Save(const proto::Checkpoint& ckpt);

  // Newest checkpoint that reads and passes `accept` (which throws CheckpointError to refuse,
  // e.g. on a config mismatch). Refused files are reported through `warn` and kept on disk.
  // Returns false when none is usable; `errors` then lists why each was refused.
  bool LoadLatestGood(const std::function<void(const proto::Checkpoint&)>& accept,
                      const std::function<void(const std::string&)>& warn, proto::Checkpoint* out,
                      std::string* path_out, std::vector<std::string>* errors) const;

 private:
  std::string dir_;
  int keep_last_;
  int milestone_every_;
};

}  // namespace perch
