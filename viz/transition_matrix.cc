#include "viz/transition_matrix.h"

#include <string>
#include <vector>

#include "common/subtasks.h"
#include "viz/canvas.h"

namespace perch {

void SaveTransitionMatrixPng(const Json& result, const std::string& path) {
  // Rows: where a run came from (the start or a subtask); columns: what followed.
  std::vector<std::string> rows = {"start"}, cols = SubtaskNames();
  for (const std::string& n : SubtaskNames()) rows.push_back(n);
  cols.push_back("end");
  const int cell = 90, label_w = 110, head_h = 60, gap = 30;
  const std::vector<std::string> sides = {"left", "right"};
  const int panel_w = label_w + cell * static_cast<int>(cols.size());
  Canvas c(gap + sides.size() * (panel_w + gap), head_h + cell * rows.size() + gap,
           Rgb{255, 255, 255});
  const Json& t = result.contains("transitions") ? result["transitions"] : Json::object();
  for (size_t p = 0; p < sides.size(); ++p) {
    const int x0 = gap + static_cast<int>(p) * (panel_w + gap);
    c.DrawText(x0, 8, "start side: " + sides[p], Rgb{0, 0, 0}, 3);
    for (size_t j = 0; j < cols.size(); ++j) {
      c.DrawText(x0 + label_w + static_cast<int>(j) * cell + 4, head_h - 18, cols[j], Rgb{0, 0, 0});
    }
    const Json side = t.contains(sides[p]) ? t[sides[p]] : Json::object();
    for (size_t i = 0; i < rows.size(); ++i) {
      const int y = head_h + static_cast<int>(i) * cell;
      c.DrawText(x0, y + cell / 2 - 5, rows[i], Rgb{0, 0, 0});
      const Json row = side.contains(rows[i]) ? side[rows[i]] : Json::object();
      int total = 0;
      for (const auto& [k, v] : row.items()) total += v.get<int>();
      for (size_t j = 0; j < cols.size(); ++j) {
        const int n = row.contains(cols[j]) ? row[cols[j]].get<int>() : 0;
        const double share = total > 0 ? static_cast<double>(n) / total : 0.0;
        const uint8_t shade = static_cast<uint8_t>(255 - 200 * share);
        const int x = x0 + label_w + static_cast<int>(j) * cell;
        c.FillRect(x, y, x + cell - 2, y + cell - 2, Rgb{shade, shade, 255});
        c.DrawText(x + 8, y + cell / 2 - 5, std::to_string(n),
                   share > 0.6 ? Rgb{255, 255, 255} : Rgb{0, 0, 0});
      }
    }
  }
  c.SavePng(path);
}

}  // namespace perch
