// Child processes for `perch train` (the local launcher), `perch bench cluster` and the tests
// that run real processes: spawn this same binary with arguments, wait with a timeout, stop.
#pragma once

#include <sys/types.h>

#include <string>
#include <vector>

namespace perch {

// Path of the running executable (/proc/self/exe).
std::string SelfExe();

// fork + exec of argv[0] with argv. stdout/stderr go to `log_path` (appended) unless empty (then
// inherited); with `stdout_path`, stdout goes there instead (truncated: a command's --json
// result). The child gets SIGTERM when the parent dies (PR_SET_PDEATHSIG), so that no
// process outlives the launcher. Throws std::runtime_error when fork fails.
pid_t Spawn(const std::vector<std::string>& argv, const std::string& log_path = "",
            const std::string& stdout_path = "");

// Waits for `pid` up to timeout_s. Returns true and sets *status (waitpid form) if it exited.
bool WaitFor(pid_t pid, double timeout_s, int* status);

// SIGTERM, wait up to grace_s, then SIGKILL and reap. Returns the waitpid status.
int Stop(pid_t pid, double grace_s);

// "exited 0", "killed by signal 9", ...
std::string DescribeStatus(int status);

// A TCP port that was free a moment ago, drawn below the kernel's ephemeral range (so no
// outgoing connection takes it before it is bound) and never handed out twice in one process.
int PickFreePort();

// When `perch train` restarts a child that died (issue 17): exponential backoff from base_s,
// doubling per failure in a row up to max_s; a child that ran at least healthy_s before it died
// starts the count again; give_up_after failures in a row with the same description (the exit
// status, the "identical failure") end the restarts (0: never give up).
struct RestartPolicyConfig {
  double base_s = 0.5;
  double max_s = 30.0;
  int give_up_after = 5;
  double healthy_s = 60.0;
};

class RestartPolicy {
 public:
  explicit RestartPolicy(const RestartPolicyConfig& c) : c_(c) {}
  // The child started at `now`.
  void OnStart(double now) { started_at_ = now; }
  // The child died at `now` as `what` (DescribeStatus). Returns the delay before the next start,
  // or -1: give up.
  double OnFailure(const std::string& what, double now);
  int failures_in_a_row() const { return in_a_row_; }
  int identical_in_a_row() const { return identical_; }
  int restarts() const { return restarts_; }

 private:
  RestartPolicyConfig c_;
  double started_at_ = 0.0;
  int in_a_row_ = 0;
  int identical_ = 0;
  int restarts_ = 0;
  std::string last_;
};

// The last n lines of a text file ("" when it cannot be read), for a give-up message.
std::string LastLines(const std::string& path, int n);

// The process state letter from /proc/PID/stat ('R', 'S', 'T' for stopped, ...; '?' if unknown).
char ProcessState(pid_t pid);

}  // namespace perch
