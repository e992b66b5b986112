// Small file helpers shared by every file format of the project (checkpoints, state banks, run
// summaries): the CRC-32 of zlib/PNG/ZIP and an atomic write.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

namespace perch {

// CRC-32 (IEEE 802.3, as zlib's crc32).
uint32_t Crc32(const void* data, size_t size);

// Writes `bytes` to `path` atomically (temporary file, fsync, rename, fsync of the directory).
// Throws std::runtime_error naming the path on failure; an existing file at `path` is left
// untouched then.
void WriteFileAtomic(const std::string& path, const std::string& bytes);

}  // namespace perch
