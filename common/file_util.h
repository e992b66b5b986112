// Small file helpers shared by every file format of the project (checkpoints, state banks, run
// summaries): reading a whole file, the CRC-32 of zlib/PNG/ZIP and an atomic write.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

namespace perch {

// CRC-32 (IEEE 802.3, as zlib's crc32).
uint32_t Crc32(const void* data, size_t size);

// The whole of `path`'s bytes. ConfigError "PATH: cannot open NOUN: <reason>" when it cannot be
// opened, "PATH: cannot read NOUN: <reason>" when reading fails (a directory, an I/O error), so a
// failed read is never taken for a shorter file.
std::string ReadFileBytes(const std::string& path, const std::string& noun = "file");

// Writes `bytes` to `path` atomically (temporary file, fsync, rename, fsync of the directory).
// Throws std::runtime_error naming the path on failure; an existing file at `path` is left
// untouched then.
void WriteFileAtomic(const std::string& path, const std::string& bytes);

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

}  // namespace perch
