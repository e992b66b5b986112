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
// inherited). The child gets SIGTERM when the parent dies (PR_SET_PDEATHSIG), so that no
// process outlives the launcher. Throws std::runtime_error when fork fails.
pid_t Spawn(const std::vector<std::string>& argv, const std::string& log_path = "");

// Waits for `pid` up to timeout_s. Returns true and sets *status (waitpid form) if it exited.
bool WaitFor(pid_t pid, double timeout_s, int* status);

// SIGTERM, wait up to grace_s, then SIGKILL and reap. Returns the waitpid status.
int Stop(pid_t pid, double grace_s);

// "exited 0", "killed by signal 9", ...
std::string DescribeStatus(int status);

// A TCP port on 127.0.0.1 that was free a moment ago (bind to port 0, read it back, close).
int PickFreePort();

}  // namespace perch
