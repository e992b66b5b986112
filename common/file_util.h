// Small file helpers shared by every file format of the project (checkpoints, state banks, run
// summaries, recipes): reading a whole file, the one CRC-32 (zlib's), the one SHA-256 (OpenSSL's),
// the one framing and the one atomic writer. Nothing else in the tree computes a checksum or
// renames a temporary file into place.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

namespace perch {

// CRC-32 (IEEE 802.3): zlib's crc32, as ZIP/NPZ and PNG use it.
uint32_t Crc32(const void* data, size_t size);

// Lower-case hex SHA-256 of `bytes` (OpenSSL's EVP), and of a file's bytes (ConfigError naming
// the file when it cannot be read).
std::string Sha256Hex(const std::string& bytes);
std::string FileSha256(const std::string& path);

// The whole of `path`'s bytes. ConfigError "PATH: cannot open NOUN: <reason>" when it cannot be
// opened, "PATH: cannot read NOUN: <reason>" when reading fails (a directory, an I/O error), so a
// failed read is never taken for a shorter file.
std::string ReadFileBytes(const std::string& path, const std::string& noun = "file");

// Writes `bytes` to `path` atomically (temporary file, fsync, rename, fsync of the directory), the
// new file with permission bits `mode` from the start (0600 for secrets). Throws ConfigError
// naming the path on failure; an existing file at `path` is left untouched then.
void WriteFileAtomic(const std::string& path, const std::string& bytes, unsigned mode = 0644);
// Moves a finished temporary file that another writer produced (a child process, gnuplot) into
// place durably: fsync `tmp`, rename it onto `path`, fsync the directory. ConfigError on failure
// (`tmp` is removed then, `path` untouched).
void CommitFileAtomic(const std::string& tmp, const std::string& path);

// The framed layout of state banks and recordings: 8-byte magic, uint32 format, uint64 payload
// length, uint32 CRC-32 of the payload (little-endian), payload.
constexpr size_t kFrameHeaderBytes = 8 + 4 + 8 + 4;
std::string FramePayload(const char (&magic)[8], uint32_t format, const std::string& payload);
// The payload of a framed file's `bytes`; ConfigError "PATH: ..." naming the kind (`noun`, e.g.
// "state bank") and the reason: no magic, another format (+ `format_hint`), a length that differs
// from the header's (truncated or corrupt), a CRC mismatch.
std::string UnframePayload(const std::string& bytes, const std::string& path,
                           const char (&magic)[8], uint32_t format, const std::string& noun,
                           const std::string& format_hint = "");

// Checkpoint files (learner/service/checkpoint.h writes them; tasks/ read the weights and config
// inside) are framed with this magic and format.
constexpr char kCheckpointMagic[8] = {'P', 'E', 'R', 'C', 'H', 'C', 'K', 'P'};
constexpr uint32_t kCheckpointFormat = 1;
// True when `bytes` start with the checkpoint magic (the file is meant to be a checkpoint).
bool HasCheckpointMagic(const std::string& bytes);

}  // namespace perch
