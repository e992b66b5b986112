#include "common/field_text.h"

#include <algorithm>
#include <array>
#include <functional>

namespace perch {

std::string DescribedFieldsText(const std::vector<std::pair<std::string, Json>>& tables) {
  std::vector<std::array<std::string, 4>> rows;  // name, default, rule, doc
  std::function<void(const Json&, const std::string&)> add = [&](const Json& t,
                                                                 const std::string& prefix) {
    for (const Json& r : t) {
      const std::string name = prefix + "." + r["name"].get<std::string>();
      if (r.contains("fields")) {
        add(r["fields"], name);
        continue;
      }
      rows.push_back({name, r.contains("default") ? r["default"].dump() : "", r.value("rule", ""),
                      r.value("doc", "")});
    }
  };
  for (const auto& [prefix, table] : tables) add(table, prefix);
  size_t w0 = 0, w1 = 0;
  for (const auto& r : rows) {
    w0 = std::max(w0, r[0].size());
    w1 = std::max(w1, std::min<size_t>(r[1].size(), 24));
  }
  std::string out;
  for (const auto& r : rows) {
    std::string line = r[0] + std::string(w0 + 2 - r[0].size(), ' ') + r[1];
    line += std::string(r[1].size() < w1 + 2 ? w1 + 2 - r[1].size() : 2, ' ') + r[3];
    if (!r[2].empty()) line += " (" + r[2] + ")";
    out += line + "\n";
  }
  return out;
}

}  // namespace perch
