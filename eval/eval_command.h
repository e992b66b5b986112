// `perch eval`: one function per kind of evaluation behind the command's flags (app/cmd_eval.cc
// parses them into EvalCommand): a subtask over seeded episodes (the task registry's evaluation),
// the scripted chain, and the meta controller on sit_chair (a meta policy or the planner, with
// its lookahead, resumable records, shards and hand-over banks). Each prints its JSON (--json)
// or a line of figures on stdout; progress goes to stderr.
#pragma once

#include <array>
#include <string>
#include <thread>
#include <vector>

#include "eval/eval_config.h"
#include "hierarchy/hierarchy.h"

namespace perch {

// --task chain's own flags.
struct ChainFlags {
  int zone = 1;
  std::array<std::string, kNumSubtasks> models = {
      "models/turn_left/policy.bin", "models/turn_right/policy.bin", "models/sit/policy.bin",
      "models/walk_stage2_fallrestart/checkpoints/ckpt-0000013900.bin"};
  ChainOptions options;
  std::string save_sit_starts;  // --chain-save-sit-starts: a bank of the states at the switch
};

struct EvalCommand {
  ConfigOverrides cfg;
  std::string model, filmstrip, record;
  int record_episodes = 0;
  bool force = false;
  EvalOptions eval;
  int frames = 6;
  int panel_px = 220;
  bool fixed_window = false;
  bool json = false;
  int trials = 0;
  std::string matrix_png;
  bool planner = false;                // sit_chair: the scripted planner decides (no --model)
  std::string save_sit_starts;         // sit_chair: a bank of the states at every hand-over to sit
  std::string save_failed_sit_starts;  // ... of the trials that failed
  std::string hand_overs_to = "sit";   // sit_chair: whose hand-overs those banks hold
  // sit_chair with a meta policy: its lookahead (only the fields of LookaheadFieldNames(): the
  // --lookahead-* flags), or all of them from a JSON file (configs/lookahead/).
  PlannerConfig lookahead;
  std::string lookahead_file;
  bool record_routes = false;  // ... and each start route's outcome in the records
  std::string start_bank = "data/banks/walk_end_poses_eval.bin";  // sit_chair: walk starts
  std::string records;  // sit_chair: per-trial records, appended as trials finish (resumes)
  int first_trial = 0;  // sit_chair: a shard's first trial
  int threads = std::max(1u, std::thread::hardware_concurrency());
  ChainFlags chain;
};

// Runs the evaluation `o` asks for; ConfigError on a bad combination of flags, before any work.
void RunEvalCommand(EvalCommand& o);

// `perch eval-merge`: the records of sit_chair evaluation shards joined into the result one
// evaluation of all their trials gives (the first `trials` from the lowest; 0: all; so_far: up
// to the first missing). ConfigError on overlapping shards, other settings or a gap.
struct EvalMergeOptions {
  std::vector<std::string> files;
  std::string matrix_png;
  int trials = 0;
  bool so_far = false;
};
Json MergeEvalRecords(EvalMergeOptions o);

}  // namespace perch
