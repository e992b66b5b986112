// Reader for NumPy .npz archives as the authors saved them (notes §7.2): an uncompressed ZIP
// ("stored") of .npy v1.x files, dtypes <f8, <f4, <i8 in C order. Pickled object arrays ('|O')
// are refused with an error that says so (use the *_plain.npz copies).
#pragma once

#include <cstdint>
#include <map>
#include <string>
#include <vector>

namespace perch {

struct NpyArray {
  std::string dtype;           // "<f8", "<f4" or "<i8"
  std::vector<int64_t> shape;  // C order; empty for a scalar
  std::vector<double> values;  // all elements as double (ints converted), C order
  std::vector<int64_t> ints;   // all elements, only for "<i8"

  int64_t size() const;
  // Element at a multi-index (checked): At({i, j, k}).
  double At(std::initializer_list<int64_t> idx) const;
};

// Parses one .npy buffer; `ctx` names it in errors. Throws ConfigError.
NpyArray ParseNpy(const std::string& bytes, const std::string& ctx);

// Reads every member "NAME.npy" of an .npz archive into a map keyed by NAME. Throws ConfigError
// "PATH: ..." for a missing file, a damaged ZIP (bad signature, size or CRC), compressed members,
// or an unsupported dtype.
std::map<std::string, NpyArray> LoadNpz(const std::string& path);

}  // namespace perch
