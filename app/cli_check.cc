#include "app/cli_check.h"

#include <algorithm>
#include <stdexcept>
#include <vector>

namespace perch {
namespace {

std::string CommandPath(const CLI::App* app) {
  std::vector<std::string> names;
  for (const CLI::App* a = app; a != nullptr; a = a->get_parent()) names.push_back(a->get_name());
  std::string s = "perch";
  for (auto it = names.rbegin(); it != names.rend(); ++it) {
    if (!it->empty() && *it != "perch") s += " " + *it;
  }
  return s;
}

std::vector<const CLI::App*> Subcommands(const CLI::App* app) {
  return app->get_subcommands([](const CLI::App*) { return true; });
}

// The nearest candidate within a third of the word's length (at least 2 edits), or "".
std::string Nearest(const std::string& word, const std::vector<std::string>& candidates) {
  std::string best;
  int best_d = 1 << 30;
  for (const std::string& c : candidates) {
    int d = EditDistance(word, c);
    // A prefix ("eval" for "evaluate") counts as near.
    if (c.size() >= 3 && word.compare(0, c.size(), c) == 0) d = std::min(d, 1);
    if (d < best_d) {
      best_d = d;
      best = c;
    }
  }
  const int limit = std::max(2, static_cast<int>(word.size()) / 3);
  return best_d <= limit ? best : std::string();
}

}  // namespace

int EditDistance(const std::string& a, const std::string& b) {
  std::vector<int> prev(b.size() + 1), cur(b.size() + 1);
  for (size_t j = 0; j <= b.size(); ++j) prev[j] = static_cast<int>(j);
  for (size_t i = 1; i <= a.size(); ++i) {
    cur[0] = static_cast<int>(i);
    for (size_t j = 1; j <= b.size(); ++j) {
      cur[j] = std::min({prev[j] + 1, cur[j - 1] + 1, prev[j - 1] + (a[i - 1] == b[j - 1] ? 0 : 1)});
    }
    std::swap(prev, cur);
  }
  return prev[b.size()];
}

std::string CheckCommandLine(const CLI::App& root, int argc, const char* const* argv) {
  const CLI::App* app = &root;
  bool chose_subcommand = false;
  for (int i = 1; i < argc; ++i) {
    const std::string tok = argv[i];
    if (tok == "--") break;
    if (tok.size() > 2 && tok.compare(0, 2, "--") == 0) {
      const std::string name = tok.substr(0, tok.find('='));
      const CLI::Option* opt = app->get_option_no_throw(name);
      if (opt == nullptr) {
        std::vector<std::string> names;
        for (const CLI::Option* o : app->get_options()) {
          for (const std::string& l : o->get_lnames()) names.push_back("--" + l);
        }
        const std::string near = Nearest(name, names);
        return name + ": unknown option of '" + CommandPath(app) + "'" +
               (near.empty() ? "" : "; did you mean " + near + "?") + " (see " + CommandPath(app) +
               " --help)";
      }
      // Skip the option's value when it takes one and it is not attached with '='.
      if (tok.find('=') == std::string::npos && opt->get_expected_min() > 0) ++i;
      continue;
    }
    if (!tok.empty() && tok[0] == '-') continue;  // short flags (-h) and negative numbers
    const std::vector<const CLI::App*> subs = Subcommands(app);
    const auto it = std::find_if(subs.begin(), subs.end(),
                                 [&](const CLI::App* s) { return s->check_name(tok); });
    if (it != subs.end()) {
      app = *it;
      chose_subcommand = false;
      continue;
    }
    if (!subs.empty() && app->get_require_subcommand_min() > 0 && !chose_subcommand) {
      std::vector<std::string> names;
      for (const CLI::App* s : subs) names.push_back(s->get_name());
      const std::string near = Nearest(tok, names);
      std::string list;
      for (const std::string& n : names) list += (list.empty() ? "" : ", ") + n;
      return "'" + tok + "': unknown subcommand of '" + CommandPath(app) + "'" +
             (near.empty() ? "" : "; did you mean '" + near + "'?") + " (one of: " + list + ")";
    }
    // A positional argument of this subcommand: CLI11 checks it.
  }
  return "";
}

std::string TakeDataDirFlag(int* argc, char** argv) {
  std::string dir;
  int out = 1;
  for (int i = 1; i < *argc; ++i) {
    const std::string tok = argv[i];
    if (tok == "--") {
      for (; i < *argc; ++i) argv[out++] = argv[i];
      break;
    }
    if (tok == "--data-dir") {
      if (i + 1 >= *argc) throw std::runtime_error("--data-dir: expected a directory");
      dir = argv[++i];
      continue;
    }
    if (tok.compare(0, 11, "--data-dir=") == 0) {
      dir = tok.substr(11);
      if (dir.empty()) throw std::runtime_error("--data-dir: expected a directory");
      continue;
    }
    argv[out++] = argv[i];
  }
  *argc = out;
  argv[out] = nullptr;
  return dir;
}

}  // namespace perch
