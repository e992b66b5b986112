// The Kubernetes manifests agree with the repository: the ConfigMap carries configs/default.json,
// and the ports actors dial are the ones the learner binds and its Service exposes.
#include <gtest/gtest.h>

#include <fstream>
#include <regex>
#include <sstream>
#include <string>

#include "common/json_util.h"

namespace perch {
namespace {

std::string Read(const std::string& rel) {
  std::ifstream in(std::string(PERCH_SOURCE_DIR) + "/" + rel);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

TEST(K8sManifests, ConfigMapIsTheDefaultConfig) {
  const std::string yaml = Read("k8s/configmap.yaml");
  const size_t at = yaml.find("config.json: |");
  ASSERT_NE(at, std::string::npos) << "k8s/configmap.yaml has no config.json block";
  std::stringstream body(yaml.substr(yaml.find('\n', at) + 1));
  std::string json_text, line;
  while (std::getline(body, line)) json_text += (line.size() >= 4 ? line.substr(4) : line) + "\n";
  const Json from_map = Json::parse(json_text);
  const Json from_repo = LoadJsonFile(std::string(PERCH_SOURCE_DIR) + "/configs/default.json");
  EXPECT_EQ(from_map, from_repo) << "k8s/configmap.yaml is stale: run scripts/gen-k8s-configmap.sh";
}

TEST(K8sManifests, ActorPortsMatchLearnerBindsAndService) {
  const std::string learner = Read("k8s/learner.yaml");
  const std::string actors = Read("k8s/actors.yaml");
  std::smatch m;
  ASSERT_TRUE(
      std::regex_search(learner, m, std::regex(R"re("--rollout-bind", "tcp://\*:(\d+)")re")));
  const std::string rollout = m[1];
  ASSERT_TRUE(
      std::regex_search(learner, m, std::regex(R"re("--weights-bind", "tcp://\*:(\d+)")re")));
  const std::string weights = m[1];
  EXPECT_NE(actors.find("\"--rollout-port\", \"" + rollout + "\""), std::string::npos);
  EXPECT_NE(actors.find("\"--weights-port\", \"" + weights + "\""), std::string::npos);
  EXPECT_NE(learner.find("port: " + rollout), std::string::npos);
  EXPECT_NE(learner.find("port: " + weights), std::string::npos);
  // Actors reach the learner through its Service name.
  ASSERT_TRUE(
      std::regex_search(learner, m, std::regex(R"re(kind: Service\s+metadata:\s+name: (\S+))re")));
  EXPECT_NE(actors.find("\"--learner-host\", \"" + std::string(m[1]) + "\""), std::string::npos);
}

// The sharded evaluation covers each of its trials once: shard i starts at i x its trial count,
// the shards together run the paper's 10,000, and each writes its own records file.
TEST(K8sManifests, EvalShardsCoverTheTrialsOnceEach) {
  const std::string yaml = Read("k8s/eval-shards.yaml");
  std::smatch m;
  ASSERT_TRUE(std::regex_search(yaml, m, std::regex(R"re(completions: (\d+))re")));
  const int shards = std::stoi(m[1]);
  ASSERT_TRUE(std::regex_search(yaml, m, std::regex(R"re(--trials (\d+))re")));
  const int per_shard = std::stoi(m[1]);
  ASSERT_TRUE(std::regex_search(
      yaml, m, std::regex(R"re(--first-trial \$\(\(JOB_COMPLETION_INDEX \* (\d+)\)\))re")));
  EXPECT_EQ(std::stoi(m[1]), per_shard);
  EXPECT_EQ(shards * per_shard, 10000);
  EXPECT_NE(yaml.find("completionMode: Indexed"), std::string::npos);
  EXPECT_TRUE(std::regex_search(yaml, std::regex(R"re(--records \S*\$JOB_COMPLETION_INDEX)re")));
  // The volume the pods write is the claim the file declares.
  ASSERT_TRUE(std::regex_search(yaml, m, std::regex(R"re(claimName: (\S+))re")));
  EXPECT_TRUE(std::regex_search(
      yaml, std::regex("kind: PersistentVolumeClaim\\s+metadata:\\s+name: " + std::string(m[1]))));
}

// The recipe's evaluation workers mount the recipe pod's own volume (its StatefulSet's claim,
// ReadWriteMany) and take shards from the recipe's --dir.
TEST(K8sManifests, RecipeEvalWorkersShareTheRecipesDirectory) {
  const std::string recipe = Read("k8s/recipe.yaml");
  const std::string workers = Read("k8s/recipe-eval-workers.yaml");
  std::smatch m;
  ASSERT_TRUE(std::regex_search(recipe, m, std::regex(R"re("--dir", "(\S+)")re")));
  const std::string dir = m[1];
  EXPECT_NE(workers.find("\"worker\", \"--dir\", \"" + dir + "\""), std::string::npos) << dir;
  ASSERT_TRUE(std::regex_search(recipe, m,
                                std::regex(R"re(kind: StatefulSet\s+metadata:\s+name: (\S+))re")));
  const std::string set = m[1];
  ASSERT_TRUE(std::regex_search(
      recipe, m, std::regex(R"re(volumeClaimTemplates:\s+- metadata:\s+name: (\S+))re")));
  EXPECT_NE(workers.find("claimName: " + std::string(m[1]) + "-" + set + "-0"), std::string::npos);
  EXPECT_NE(recipe.find("accessModes: [\"ReadWriteMany\"]"), std::string::npos);
  // Both mount it where the recipe's directory is.
  const std::string top = dir.substr(0, dir.find('/', 1));
  EXPECT_NE(workers.find("mountPath: " + top), std::string::npos) << top;
}

}  // namespace
}  // namespace perch
