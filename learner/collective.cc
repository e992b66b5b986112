#include "learner/collective.h"

#include <cstdint>
#include <cstring>

namespace perch {

namespace {
void PutU32(std::string* s, uint32_t v) { s->append(reinterpret_cast<const char*>(&v), 4); }

}  // namespace

std::string PackStrings(const std::vector<std::string>& parts) {
  std::string out;
  PutU32(&out, static_cast<uint32_t>(parts.size()));
  for (const std::string& p : parts) {
    PutU32(&out, static_cast<uint32_t>(p.size()));
    out += p;
  }
  return out;
}

std::vector<std::string> UnpackStrings(const std::string& packed, const std::string& ctx) {
  size_t pos = 0;
  auto u32 = [&]() {
    if (packed.size() - pos < 4) throw std::runtime_error(ctx + ": truncated");
    uint32_t v;
    std::memcpy(&v, packed.data() + pos, 4);
    pos += 4;
    return v;
  };
  const uint32_t n = u32();
  if (n > packed.size())
    throw std::runtime_error(ctx + ": count " + std::to_string(n) + " too big");
  std::vector<std::string> parts(n);
  for (uint32_t i = 0; i < n; ++i) {
    const uint32_t len = u32();
    if (packed.size() - pos < len) throw std::runtime_error(ctx + ": truncated");
    parts[i] = packed.substr(pos, len);
    pos += len;
  }
  if (pos != packed.size()) throw std::runtime_error(ctx + ": trailing bytes");
  return parts;
}

}  // namespace perch
