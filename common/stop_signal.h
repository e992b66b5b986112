// How a long-running command (perch learner, actor, train, recipe run, the benches) stops: SIGINT
// and SIGTERM set one flag that its loops poll, so that it ends at a safe point (a checkpoint, a
// finished stage) rather than mid-write; and where its logs go (stderr; stdout is for --json).
#pragma once

#include <atomic>
#include <string>

namespace perch {

// The process's stop flag: set by SIGINT/SIGTERM once InstallStopHandlers has run.
std::atomic<bool>& StopFlag();

// SIGINT and SIGTERM set StopFlag() (without SA_RESTART, so that blocking calls return and loops
// see it); SIGPIPE is ignored (a closed pipe is an error return, not a death).
void InstallStopHandlers();

// spdlog's default logger writes to stderr, each line tagged "[HH:MM:SS.mmm] [name]".
void LogToStderr(const std::string& name);

}  // namespace perch
