#include "common/npz.h"

#include <cstring>
#include <sstream>

#include "common/file_util.h"
#include "common/json_util.h"

namespace perch {
namespace {

// Little-endian reads with bounds checks.
class Reader {
 public:
  Reader(const std::string& buf, const std::string& ctx) : buf_(buf), ctx_(ctx) {}
  uint64_t Le(size_t off, int bytes) const {
    if (off + bytes > buf_.size()) throw ConfigError(ctx_ + ": truncated (read past end)");
    uint64_t v = 0;
    for (int i = bytes - 1; i >= 0; --i) v = (v << 8) | static_cast<uint8_t>(buf_[off + i]);
    return v;
  }

 private:
  const std::string& buf_;
  const std::string& ctx_;
};

// Value of 'key': ... in a .npy header dict (a Python literal).
std::string HeaderField(const std::string& h, const std::string& key, const std::string& ctx) {
  const std::string pat = "'" + key + "'";
  const size_t k = h.find(pat);
  if (k == std::string::npos) throw ConfigError(ctx + ": npy header lacks '" + key + "'");
  size_t p = h.find(':', k + pat.size());
  if (p == std::string::npos) throw ConfigError(ctx + ": malformed npy header");
  ++p;
  while (p < h.size() && h[p] == ' ') ++p;
  if (p >= h.size()) throw ConfigError(ctx + ": malformed npy header");
  size_t e = p;
  if (h[p] == '\'') {
    e = h.find('\'', p + 1);
    if (e == std::string::npos) throw ConfigError(ctx + ": malformed npy header");
    return h.substr(p + 1, e - p - 1);
  }
  if (h[p] == '(') {
    e = h.find(')', p);
    if (e == std::string::npos) throw ConfigError(ctx + ": malformed npy header");
    return h.substr(p, e - p + 1);
  }
  while (e < h.size() && h[e] != ',' && h[e] != '}') ++e;
  return h.substr(p, e - p);
}

}  // namespace

int64_t NpyArray::size() const {
  int64_t n = 1;
  for (int64_t d : shape) n *= d;
  return n;
}

double NpyArray::At(std::initializer_list<int64_t> idx) const {
  if (idx.size() != shape.size()) throw std::out_of_range("NpyArray::At: wrong number of indices");
  int64_t flat = 0;
  size_t d = 0;
  for (int64_t i : idx) {
    if (i < 0 || i >= shape[d]) throw std::out_of_range("NpyArray::At: index out of range");
    flat = flat * shape[d] + i;
    ++d;
  }
  return values[flat];
}

NpyArray ParseNpy(const std::string& b, const std::string& ctx) {
  if (b.size() < 10 || std::memcmp(b.data(), "\x93NUMPY", 6) != 0) {
    throw ConfigError(ctx + ": not an .npy array (bad magic)");
  }
  Reader r(b, ctx);
  const int major = static_cast<uint8_t>(b[6]);
  size_t hlen = 0, hoff = 0;
  if (major == 1) {
    hlen = r.Le(8, 2);
    hoff = 10;
  } else if (major == 2 || major == 3) {
    hlen = r.Le(8, 4);
    hoff = 12;
  } else {
    throw ConfigError(ctx + ": unsupported .npy version " + std::to_string(major));
  }
  if (hoff + hlen > b.size()) throw ConfigError(ctx + ": truncated .npy header");
  const std::string h = b.substr(hoff, hlen);
  NpyArray a;
  a.dtype = HeaderField(h, "descr", ctx);
  if (a.dtype == "|O") {
    throw ConfigError(ctx +
                      ": dtype '|O' is a pickled Python object array, which cannot be read "
                      "without a pickle parser; use the *_plain.npz copy");
  }
  int elem = 0;
  if (a.dtype == "<f8" || a.dtype == "<i8") {
    elem = 8;
  } else if (a.dtype == "<f4") {
    elem = 4;
  } else {
    throw ConfigError(ctx + ": unsupported dtype '" + a.dtype + "' (supported: <f8 <f4 <i8)");
  }
  if (HeaderField(h, "fortran_order", ctx) != "False") {
    throw ConfigError(ctx + ": Fortran-order arrays are not supported");
  }
  std::string shape = HeaderField(h, "shape", ctx);
  for (char& c : shape) {
    if (c == '(' || c == ')' || c == ',') c = ' ';
  }
  std::istringstream ss(shape);
  int64_t d;
  while (ss >> d) {
    if (d < 0) throw ConfigError(ctx + ": negative dimension in shape");
    a.shape.push_back(d);
  }
  if (!ss.eof()) throw ConfigError(ctx + ": malformed shape in npy header");
  const size_t data_off = hoff + hlen;
  const int64_t n = a.size();
  if (b.size() - data_off != static_cast<size_t>(n) * elem) {
    throw ConfigError(ctx + ": data size " + std::to_string(b.size() - data_off) +
                      " bytes does not match shape (" + std::to_string(n * elem) + " expected)");
  }
  a.values.resize(n);
  const char* p = b.data() + data_off;
  for (int64_t i = 0; i < n; ++i) {
    if (elem == 4) {
      float f;
      std::memcpy(&f, p + 4 * i, 4);
      a.values[i] = f;
    } else if (a.dtype == "<f8") {
      std::memcpy(&a.values[i], p + 8 * i, 8);
    } else {
      int64_t v;
      std::memcpy(&v, p + 8 * i, 8);
      a.ints.push_back(v);
      a.values[i] = static_cast<double>(v);
    }
  }
  return a;
}

std::map<std::string, NpyArray> LoadNpz(const std::string& path) {
  const std::string buf = ReadFileBytes(path);
  Reader r(buf, path);
  // End-of-central-directory record: 22 bytes plus an optional comment at the end of the file.
  if (buf.size() < 22) throw ConfigError(path + ": not a ZIP archive (too short)");
  size_t eocd = std::string::npos;
  for (size_t i = buf.size() - 22 + 1; i-- > 0 && buf.size() - i <= 22 + 65535;) {
    if (r.Le(i, 4) == 0x06054b50u) {
      eocd = i;
      break;
    }
  }
  if (eocd == std::string::npos) throw ConfigError(path + ": not a ZIP archive (no end record)");
  const uint64_t entries = r.Le(eocd + 10, 2);
  uint64_t cd = r.Le(eocd + 16, 4);
  std::map<std::string, NpyArray> out;
  for (uint64_t e = 0; e < entries; ++e) {
    if (r.Le(cd, 4) != 0x02014b50u) {
      throw ConfigError(path + ": damaged ZIP central directory (entry " + std::to_string(e) + ")");
    }
    const uint64_t method = r.Le(cd + 10, 2);
    const uint32_t crc = static_cast<uint32_t>(r.Le(cd + 16, 4));
    uint64_t csize = r.Le(cd + 20, 4);
    uint64_t usize = r.Le(cd + 24, 4);
    const uint64_t nlen = r.Le(cd + 28, 2), xlen = r.Le(cd + 30, 2), clen = r.Le(cd + 32, 2);
    uint64_t local = r.Le(cd + 42, 4);
    if (cd + 46 + nlen > buf.size()) throw ConfigError(path + ": truncated ZIP central directory");
    const std::string name = buf.substr(cd + 46, nlen);
    // Zip64 extra field (id 1) carries the sizes/offset that are 0xFFFFFFFF above.
    for (uint64_t x = cd + 46 + nlen; x + 4 <= cd + 46 + nlen + xlen;) {
      const uint64_t id = r.Le(x, 2), sz = r.Le(x + 2, 2);
      if (id == 1) {
        uint64_t q = x + 4;
        if (usize == 0xFFFFFFFFu) usize = r.Le(q, 8), q += 8;
        if (csize == 0xFFFFFFFFu) csize = r.Le(q, 8), q += 8;
        if (local == 0xFFFFFFFFu) local = r.Le(q, 8), q += 8;
      }
      x += 4 + sz;
    }
    const std::string ctx = path + ": member '" + name + "'";
    if (method != 0) {
      throw ConfigError(ctx + ": compressed (method " + std::to_string(method) +
                        "); only stored (uncompressed) archives are supported");
    }
    if (csize != usize) throw ConfigError(ctx + ": stored sizes disagree");
    if (r.Le(local, 4) != 0x04034b50u) throw ConfigError(ctx + ": bad local header signature");
    const uint64_t data = local + 30 + r.Le(local + 26, 2) + r.Le(local + 28, 2);
    if (data + csize > buf.size()) throw ConfigError(ctx + ": truncated data");
    if (Crc32(buf.data() + data, csize) != crc) {
      throw ConfigError(ctx + ": CRC mismatch (the file is corrupt)");
    }
    std::string key = name;
    if (key.size() > 4 && key.compare(key.size() - 4, 4, ".npy") == 0) key.resize(key.size() - 4);
    out[key] = ParseNpy(buf.substr(data, csize), ctx);
    cd += 46 + nlen + xlen + clen;
  }
  return out;
}

}  // namespace perch
