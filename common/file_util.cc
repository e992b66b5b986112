#include "common/file_util.h"

#include <fcntl.h>
#include <openssl/evp.h>
#include <sys/stat.h>
#include <unistd.h>
#include <zlib.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <stdexcept>

#include "common/json_util.h"

namespace perch {
namespace {

std::string DirOf(const std::string& path) {
  const size_t slash = path.find_last_of('/');
  if (slash == std::string::npos) return ".";
  return slash == 0 ? "/" : path.substr(0, slash);
}

}  // namespace

uint32_t Crc32(const void* data, size_t size) {
  // zlib takes a uInt length; feed larger buffers in pieces.
  uLong crc = crc32(0L, Z_NULL, 0);
  const auto* p = static_cast<const Bytef*>(data);
  while (size > 0) {
    const uInt n = static_cast<uInt>(std::min<size_t>(size, 1u << 30));
    crc = crc32(crc, p, n);
    p += n;
    size -= n;
  }
  return static_cast<uint32_t>(crc);
}

std::string Sha256Hex(const std::string& bytes) {
  unsigned char md[EVP_MAX_MD_SIZE];
  unsigned int len = 0;
  if (EVP_Digest(bytes.data(), bytes.size(), md, &len, EVP_sha256(), nullptr) != 1) {
    throw std::runtime_error("SHA-256 failed");
  }
  static const char* hex = "0123456789abcdef";
  std::string out;
  for (unsigned int i = 0; i < len; ++i) {
    out.push_back(hex[md[i] >> 4]);
    out.push_back(hex[md[i] & 15]);
  }
  return out;
}

std::string FileSha256(const std::string& path) { return Sha256Hex(ReadFileBytes(path)); }

std::string ReadFileBytes(const std::string& path, const std::string& noun) {
  // POSIX reads, not an ifstream: a stream's read error (a directory, an I/O error) would look
  // like a shorter file.
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) throw ConfigError(path + ": cannot open " + noun + ": " + std::strerror(errno));
  std::string bytes;
  char buf[1 << 16];
  for (;;) {
    const ssize_t n = ::read(fd, buf, sizeof(buf));
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) {
      const int err = errno;
      ::close(fd);
      throw ConfigError(path + ": cannot read " + noun + ": " + std::strerror(err));
    }
    if (n == 0) break;
    bytes.append(buf, static_cast<size_t>(n));
  }
  ::close(fd);
  return bytes;
}

void WriteFileAtomic(const std::string& path, const std::string& bytes, unsigned mode) {
  const std::string tmp = path + ".tmp";
  const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, mode);
  if (fd < 0) throw ConfigError(tmp + ": cannot create: " + std::strerror(errno));
  // A leftover temporary file keeps its old mode; set it before any byte is written.
  ::fchmod(fd, mode);
  size_t off = 0;
  while (off < bytes.size()) {
    const ssize_t n = ::write(fd, bytes.data() + off, bytes.size() - off);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      const std::string err = n < 0 ? std::strerror(errno) : "no progress";
      ::close(fd);
      ::unlink(tmp.c_str());
      throw ConfigError(tmp + ": write failed: " + err);
    }
    off += static_cast<size_t>(n);
  }
  if (::close(fd) != 0) {
    const std::string err = std::strerror(errno);
    ::unlink(tmp.c_str());
    throw ConfigError(tmp + ": close failed: " + err);
  }
  CommitFileAtomic(tmp, path);
}

void CommitFileAtomic(const std::string& tmp, const std::string& path) {
  const int fd = ::open(tmp.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) throw ConfigError(tmp + ": cannot open: " + std::strerror(errno));
  if (::fsync(fd) != 0) {
    const std::string err = std::strerror(errno);
    ::close(fd);
    ::unlink(tmp.c_str());
    throw ConfigError(tmp + ": fsync failed: " + err);
  }
  ::close(fd);
  if (std::rename(tmp.c_str(), path.c_str()) != 0) {
    const std::string err = std::strerror(errno);
    ::unlink(tmp.c_str());
    throw ConfigError(path + ": rename failed: " + err);
  }
  // Make the rename itself durable.
  const int dfd = ::open(DirOf(path).c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (dfd >= 0) {
    ::fsync(dfd);
    ::close(dfd);
  }
}

namespace {

void PutLe(std::string* s, uint64_t v, int bytes) {
  for (int i = 0; i < bytes; ++i) s->push_back(static_cast<char>((v >> (8 * i)) & 0xff));
}
uint64_t GetLe(const std::string& s, size_t at, int bytes) {
  uint64_t v = 0;
  for (int i = 0; i < bytes; ++i) {
    v |= static_cast<uint64_t>(static_cast<uint8_t>(s[at + i])) << (8 * i);
  }
  return v;
}

}  // namespace

std::string FramePayload(const char (&magic)[8], uint32_t format, const std::string& payload) {
  std::string out(magic, 8);
  PutLe(&out, format, 4);
  PutLe(&out, payload.size(), 8);
  PutLe(&out, Crc32(payload.data(), payload.size()), 4);
  return out + payload;
}

std::string UnframePayload(const std::string& bytes, const std::string& path,
                           const char (&magic)[8], uint32_t format, const std::string& noun,
                           const std::string& format_hint) {
  if (bytes.size() < kFrameHeaderBytes || std::memcmp(bytes.data(), magic, 8) != 0) {
    throw ConfigError(path + ": not a " + noun + " (no " + std::string(magic, 8) + " header; " +
                      std::to_string(bytes.size()) + " bytes)");
  }
  const uint32_t got = static_cast<uint32_t>(GetLe(bytes, 8, 4));
  if (got != format) {
    throw ConfigError(path + ": " + noun + " format " + std::to_string(got) +
                      ", this build reads " + std::to_string(format) + format_hint);
  }
  const uint64_t len = GetLe(bytes, 12, 8);
  if (bytes.size() - kFrameHeaderBytes != len) {
    throw ConfigError(path + ": " + noun + " payload is " +
                      std::to_string(bytes.size() - kFrameHeaderBytes) +
                      " bytes, its header says " + std::to_string(len) + " (truncated or corrupt)");
  }
  std::string payload = bytes.substr(kFrameHeaderBytes);
  if (Crc32(payload.data(), payload.size()) != static_cast<uint32_t>(GetLe(bytes, 20, 4))) {
    throw ConfigError(path + ": " + noun + " CRC-32 mismatch (corrupt)");
  }
  return payload;
}

bool HasCheckpointMagic(const std::string& bytes) {
  return bytes.size() >= 8 && std::memcmp(bytes.data(), kCheckpointMagic, 8) == 0;
}

}  // namespace perch
