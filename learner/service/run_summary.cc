#include "learner/service/run_summary.h"

#include <stdlib.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <sstream>

#include "common/file_util.h"
#include "learner/service/checkpoint.h"

namespace perch {

namespace {

double Num(const Json& row, const char* key, const std::string& where) {
  if (!row.contains(key) || !row[key].is_number()) {
    throw ConfigError(where + ": field '" + key + "' missing or not a number");
  }
  return row[key].get<double>();
}

}  // namespace

RunSummary SummarizeRun(const std::string& run_dir) {
  RunSummary s;
  s.run_dir = run_dir;
  const std::string path = run_dir + "/metrics.jsonl";
  std::ifstream in(path);
  if (!in) throw ConfigError(path + ": cannot open (is --run-dir a run directory?)");
  std::map<int64_t, CurveRow> by_update;
  std::string line;
  int lineno = 0;
  while (std::getline(in, line)) {
    ++lineno;
    if (line.empty()) continue;
    const std::string where = path + ":" + std::to_string(lineno);
    Json row;
    try {
      row = Json::parse(line);
    } catch (const Json::parse_error& e) {
      // A run killed mid-write leaves a torn last line; anything else is damage.
      if (in.peek() == EOF) break;
      throw ConfigError(where + ": not JSON (" + e.what() + ")");
    }
    if (!row.is_object()) throw ConfigError(where + ": not a JSON object");
    CurveRow r;
    r.update = static_cast<int64_t>(Num(row, "update", where));
    r.samples = static_cast<int64_t>(Num(row, "samples", where));
    r.time_s = Num(row, "time_s", where);
    r.samples_per_s = Num(row, "samples_per_s", where);
    r.policy_lag_mean = Num(row, "policy_lag_mean", where);
    r.actors = row.value("actors", 0);
    if (row.contains("episodes") && row["episodes"].is_number()) {
      r.episodes = row["episodes"].get<int64_t>();
    }
    if (row.contains("episodes_terminated") && row["episodes_terminated"].is_number()) {
      r.episodes_terminated = row["episodes_terminated"].get<int64_t>();
    }
    if (row.contains("episodes_judged") && row["episodes_judged"].is_number()) {
      r.episodes_judged = row["episodes_judged"].get<int64_t>();
    }
    if (row.contains("episodes_succeeded") && row["episodes_succeeded"].is_number()) {
      r.episodes_succeeded = row["episodes_succeeded"].get<int64_t>();
    }
    r.has_episodes = row.contains("return_mean") && row["return_mean"].is_number();
    if (r.has_episodes) {
      r.return_mean = row["return_mean"].get<double>();
      r.episode_length_mean = Num(row, "episode_length_mean", where);
    }
    if (row.contains("ppo") && row["ppo"].is_object()) {
      r.log_std_mean = row["ppo"].value("log_std_mean", 0.0);
    }
    by_update[r.update] = r;  // a resumed run repeats the updates after its checkpoint
  }
  if (by_update.empty()) throw ConfigError(path + ": no rows");
  for (const auto& [u, r] : by_update) {
    s.curve.push_back(r);
    s.max_actors = std::max(s.max_actors, r.actors);
  }
  s.updates = s.curve.back().update;
  s.samples = s.curve.back().samples;
  s.wall_time_s = s.curve.back().time_s;
  const std::string cfg = run_dir + "/config.json";
  if (std::filesystem::exists(cfg)) s.config = LoadJsonFile(cfg);
  const std::string ckdir = run_dir + "/checkpoints";
  if (std::filesystem::is_directory(ckdir)) {
    for (const auto& e : std::filesystem::directory_iterator(ckdir)) {
      const std::string name = e.path().filename().string();
      if (name.rfind("ckpt-", 0) == 0 && e.path().extension() == ".bin") {
        s.checkpoints.push_back(e.path().string());
      }
    }
    std::sort(s.checkpoints.begin(), s.checkpoints.end());  // zero-padded update numbers
  }
  return s;
}

void WriteCurveCsv(const RunSummary& s, const std::string& path) {
  std::ostringstream o;
  o << "update,samples,time_s,samples_per_s,return_mean,episode_length_mean,policy_lag_mean,"
       "log_std_mean,actors\n";
  o.precision(6);
  for (const CurveRow& r : s.curve) {
    o << r.update << ',' << r.samples << ',' << std::fixed << r.time_s << ',' << r.samples_per_s
      << ',';
    if (r.has_episodes)
      o << r.return_mean << ',' << r.episode_length_mean;
    else
      o << ',';
    o << ',' << r.policy_lag_mean << ',' << r.log_std_mean << ',' << r.actors << '\n';
    o.unsetf(std::ios::fixed);
  }
  WriteFileAtomic(path, o.str());
}

Json ToJson(const RunSummary& s) {
  double ret = 0, len = 0;
  int n = 0;
  for (auto it = s.curve.rbegin(); it != s.curve.rend() && n < 10; ++it) {
    if (!it->has_episodes) continue;
    ret += it->return_mean;
    len += it->episode_length_mean;
    ++n;
  }
  return Json{{"run_dir", s.run_dir},
              {"updates", s.updates},
              {"samples", s.samples},
              {"wall_time_s", s.wall_time_s},
              {"samples_per_s", s.wall_time_s > 0 ? s.samples / s.wall_time_s : 0.0},
              {"max_actors", s.max_actors},
              {"checkpoints", s.checkpoints},
              {"last",
               {{"updates_averaged", n},
                {"return_mean", n ? Json(ret / n) : Json(nullptr)},
                {"episode_length_mean", n ? Json(len / n) : Json(nullptr)}}}};
}

void PlotRuns(const std::vector<RunSummary>& runs, const std::string& png_path) {
  if (runs.empty()) throw ConfigError("plot: no runs");
  namespace fs = std::filesystem;
  char tmpl[] = "/tmp/perch-plot-XXXXXX";
  if (::mkdtemp(tmpl) == nullptr) throw ConfigError("plot: cannot make a temporary directory");
  const fs::path dir(tmpl);
  // One whitespace-separated data file per run: samples (M), hours, return, length, fall rate,
  // samples/s ("NaN" where a batch ended no episode, which gnuplot skips).
  std::vector<std::string> files;
  bool has[5] = {false, false, false, false, false};  // return, length, falls, success, samples/s
  for (size_t i = 0; i < runs.size(); ++i) {
    const fs::path f = dir / ("run" + std::to_string(i) + ".dat");
    std::ofstream o(f);
    for (const CurveRow& r : runs[i].curve) {
      o << r.samples / 1e6 << ' ' << r.time_s / 3600.0 << ' ';
      if (r.has_episodes)
        o << r.return_mean << ' ' << r.episode_length_mean << ' ';
      else
        o << "NaN NaN ";
      if (r.episodes > 0)
        o << static_cast<double>(r.episodes_terminated) / r.episodes << ' ';
      else
        o << "NaN ";
      if (r.episodes_judged > 0) {
        o << static_cast<double>(r.episodes_succeeded) / r.episodes_judged << ' ';
      } else {
        o << "NaN ";
      }
      o << r.samples_per_s << '\n';
      has[0] = has[1] = has[0] || r.has_episodes;
      has[2] = has[2] || r.episodes > 0;
      has[3] = has[3] || r.episodes_judged > 0;
      has[4] = true;
    }
    files.push_back(f.string());
  }
  std::ostringstream g;
  g << "set terminal pngcairo size 1400,1700 font ',10'\n"
    << "set output '" << png_path << ".tmp'\n"
    << "set datafile missing 'NaN'\nset grid\nset key bottom right\n"
    << "set multiplot layout 5,2 title 'Perch learning curves'\n";
  const char* names[5] = {"return (episode mean)", "episode length (control steps)",
                          "fall rate (terminated / ended)", "success rate (training episodes)",
                          "samples/s"};
  const int cols[5] = {3, 4, 5, 6, 7};
  for (int k = 0; k < 5; ++k) {
    for (int x = 0; x < 2; ++x) {
      g << "set xlabel '" << (x == 0 ? "samples (M)" : "wall time (h)") << "'\nset ylabel '"
        << names[k] << "'\n";
      if (!has[k]) {
        // No run logged this quantity (e.g. metrics from before it was logged): an empty panel.
        g << "plot [0:1] [0:1] 2 title 'no data'\n";
        continue;
      }
      g << "plot ";
      for (size_t i = 0; i < files.size(); ++i) {
        std::string label = runs[i].run_dir;
        for (char& c : label) {
          if (c == '_' || c == '\'') c = ' ';  // gnuplot's enhanced text, quoting
        }
        g << (i ? ", " : "") << "'" << files[i] << "' using " << (x + 1) << ":" << cols[k]
          << " with lines lw 1.5 title '" << label << "'";
      }
      g << "\n";
    }
  }
  g << "unset multiplot\nset output\n";
  const fs::path script = dir / "plot.gp";
  std::ofstream(script) << g.str();
  const std::string cmd = "gnuplot '" + script.string() + "' 2>" + (dir / "gnuplot.err").string();
  const int rc = std::system(cmd.c_str());
  std::ifstream err(dir / "gnuplot.err");
  const std::string err_text((std::istreambuf_iterator<char>(err)), {});
  if (rc != 0 || !fs::exists(png_path + ".tmp")) {
    throw ConfigError("plot: gnuplot failed (exit " + std::to_string(rc) +
                      "; install gnuplot-nox): " + err_text.substr(0, 400));
  }
  CommitFileAtomic(png_path + ".tmp", png_path);
  fs::remove_all(dir);
}

}  // namespace perch
