// Runs the perch program ($PERCH_BIN, set by CTest) as a user does, through the shell, for the
// tests that check commands end to end. `args` may carry shell redirections (2>&1, 2>/dev/null).
#pragma once

#include <sys/wait.h>

#include <cstdio>
#include <cstdlib>
#include <string>

namespace perch {
namespace testing_util {

struct PerchResult {
  int code;         // exit status; -1 when it did not exit normally or could not start
  std::string out;  // what it wrote to the pipe (stdout, plus stderr if redirected there)
};

inline PerchResult RunPerch(const std::string& args) {
  const char* bin = std::getenv("PERCH_BIN");
  if (bin == nullptr) return {-1, ""};
  FILE* p = popen((std::string(bin) + " " + args).c_str(), "r");
  if (p == nullptr) return {-1, ""};
  std::string out;
  char buf[4096];
  size_t n;
  while ((n = fread(buf, 1, sizeof(buf), p)) > 0) out.append(buf, n);
  const int status = pclose(p);
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, out};
}

}  // namespace testing_util
}  // namespace perch
