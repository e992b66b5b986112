// perch bench cluster, flow, scale, group, train: flags into the options structs of
// bench/cluster_bench.h, whose functions run the benchmarks.
#include <memory>

#include "app/commands.h"
#include "bench/cluster_bench.h"

namespace perch {

namespace {

// perch bench flow
void RegisterBenchFlow(CLI::App& bench) {
  auto ff = std::make_shared<BenchFlowFlags>();
  CLI::App* fl = bench.add_subcommand(
      "flow", "Flow control: stale drops, learner samples/s and actor CPU with and without credit");
  fl->add_option("--config", ff->config, "experiment config (default: the mock env)");
  fl->add_option("--actors", ff->actors, "actor process counts, e.g. 1,4,16")->delimiter(',');
  fl->add_option("--seconds", ff->seconds, "duration of each run");
  fl->add_flag("--json", ff->json, "print one JSON object");
  fl->callback([ff] {
    const int rc = RunBenchFlow(*ff);
    if (rc != 0) throw CLI::RuntimeError(rc);
  });
}

// perch bench scale
void RegisterBenchScale(CLI::App& bench) {
  auto scf = std::make_shared<BenchScaleFlags>();
  CLI::App* sc = bench.add_subcommand(
      "scale", "One learner fed by N synthetic actors (recorded segments replayed over loopback)");
  sc->add_option("--config", scf->config, "experiment config (default: walk)");
  sc->add_option("--actors", scf->actors, "synthetic actor counts, e.g. 1,16,256")->delimiter(',');
  sc->add_option("--rate", scf->rate, "samples/s per synthetic actor (default: one actor core's)");
  sc->add_option("--seconds", scf->seconds, "duration of each run");
  sc->add_option("--envs", scf->envs, "streams per synthetic actor (default: the config's)");
  sc->add_option("--ppo-threads", scf->ppo_threads, "the learner's ppo.threads (default: config)");
  sc->add_option("--record", scf->record, "segments recorded from the real env and replayed");
  sc->add_option("--learners", scf->learners,
                 "learner group sizes (cluster.learners), e.g. 1,2; actors round-robin")
      ->delimiter(',');
  sc->add_flag("--json", scf->json, "print one JSON object");
  sc->callback([scf] {
    const int rc = RunBenchScale(*scf);
    if (rc != 0) throw CLI::RuntimeError(rc);
  });
}

// perch bench group
void RegisterBenchGroup(CLI::App& bench) {
  auto gf = std::make_shared<BenchGroupFlags>();
  CLI::App* g = bench.add_subcommand(
      "group", "The learner group's gradient all-reduce over loopback TCP, per operation");
  g->add_option("--config", gf->config, "experiment config (its policy's size; default: walk)");
  g->add_option("--learners", gf->learners, "group sizes, e.g. 2,4")->delimiter(',');
  g->add_option("--ops", gf->ops, "all-reduces timed per group size");
  g->add_flag("--json", gf->json, "print one JSON object");
  g->callback([gf] {
    const int rc = RunBenchGroup(*gf);
    if (rc != 0) throw CLI::RuntimeError(rc);
  });
}

// perch bench cluster
void RegisterBenchCluster(CLI::App& bench) {
  auto bf = std::make_shared<BenchFlags>();
  CLI::App* b = bench.add_subcommand("cluster", "Cluster throughput vs the env alone");
  b->add_option("--config", bf->config, "experiment config");
  b->add_option("--actors", bf->actors, "actor processes (default: one per core)");
  b->add_option("--envs", bf->envs, "envs per actor");
  b->add_option("--env-seconds", bf->env_seconds, "duration of the env-only baseline");
  b->add_option("--cluster-seconds", bf->cluster_seconds, "duration of each cluster run");
  b->add_option("--repeats", bf->repeats, "cluster runs, each between two env-only runs");
  b->add_flag("--train-policy", bf->train_policy,
              "let the policy learn (default: learning rate 1e-12, the env-only runs' policy)");
  b->add_flag("--json", bf->json, "print one JSON object");
  b->callback([bf] {
    const int rc = RunBenchCluster(*bf);
    if (rc != 0) throw CLI::RuntimeError(rc);
  });
}

// perch bench train
void RegisterBenchTrain(CLI::App& bench) {
  auto tb = std::make_shared<BenchTrainFlags>();
  CLI::App* bt = bench.add_subcommand(
      "train", "A short training run (learner + actors) with baseline and candidate settings");
  bt->add_option("--config", tb->config, "experiment config (default: configs/default.json, walk)");
  bt->add_option("--actors", tb->actors, "actor processes (default: one per core)");
  bt->add_option("--envs", tb->envs, "envs per actor");
  bt->add_option("--updates", tb->updates, "PPO updates per run (the first is start-up)");
  bt->add_option("--rounds", tb->rounds, "runs of each arm, in ABBA order");
  bt->add_option("--baseline-physics", tb->baseline_physics,
                 "legacy (physics before issue 19) or config (as the config says)");
  bt->add_option("--candidate-physics", tb->candidate_physics, "config or legacy");
  bt->add_option("--baseline-exe", tb->baseline_exe,
                 "perch program for the baseline arm (default: this one), e.g. another build");
  bt->add_option("--candidate-exe", tb->candidate_exe, "perch program for the candidate arm");
  bt->add_option("--timeout-s", tb->timeout_s, "give up on a run after this long");
  bt->add_flag("--json", tb->json, "print one JSON object");
  bt->callback([tb] {
    const int rc = RunBenchTrain(*tb);
    if (rc != 0) throw CLI::RuntimeError(rc);
  });
}

}  // namespace

void RegisterBenchCommands(CLI::App& /*root*/, CLI::App& bench) {
  RegisterBenchFlow(bench);
  RegisterBenchScale(bench);
  RegisterBenchGroup(bench);
  RegisterBenchCluster(bench);
  RegisterBenchTrain(bench);
}

}  // namespace perch
