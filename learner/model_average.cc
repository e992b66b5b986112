#include "learner/model_average.h"

#include <algorithm>
#include <string>

#include "common/json_util.h"
#include "common/proto/model.pb.h"

namespace perch {

proto::ModelWeights AverageModels(const std::vector<proto::ModelWeights>& models) {
  if (models.empty()) throw ConfigError("average: no models given");
  const proto::ModelWeights& first = models.front();
  const int np = first.params_size();
  const int dim = first.obs_stats().mean_size();
  const std::string shape = first.shape().SerializeAsString();
  for (size_t i = 1; i < models.size(); ++i) {
    const proto::ModelWeights& m = models[i];
    const std::string ctx = "average: model " + std::to_string(i);
    if (m.shape().SerializeAsString() != shape) throw ConfigError(ctx + ": shape differs from model 0");
    if (m.params_size() != np) {
      throw ConfigError(ctx + ": " + std::to_string(m.params_size()) + " params, model 0 has " +
                        std::to_string(np));
    }
    if (m.normalize_obs() != first.normalize_obs() || m.obs_clip() != first.obs_clip() ||
        m.obs_eps() != first.obs_eps()) {
      throw ConfigError(ctx + ": observation normalization settings differ from model 0");
    }
    if (m.obs_stats().mean_size() != dim || m.obs_stats().var_size() != dim) {
      throw ConfigError(ctx + ": observation statistics have another dimension than model 0");
    }
  }
  if (first.obs_stats().var_size() != dim) {
    throw ConfigError("average: model 0: observation mean and var lengths differ");
  }

  const double n = static_cast<double>(models.size());
  std::vector<double> params(np, 0.0), mean(dim, 0.0), second(dim, 0.0);
  double count = 0.0;
  uint64_t version = 0;
  for (const proto::ModelWeights& m : models) {
    for (int k = 0; k < np; ++k) params[k] += m.params(k);
    for (int d = 0; d < dim; ++d) {
      const double mu = m.obs_stats().mean(d);
      mean[d] += mu;
      second[d] += m.obs_stats().var(d) + mu * mu;
    }
    count += m.obs_stats().count();
    version = std::max<uint64_t>(version, m.version());
  }

  proto::ModelWeights out = first;
  out.set_version(version);
  for (int k = 0; k < np; ++k) out.set_params(k, static_cast<float>(params[k] / n));
  proto::RunningStats* st = out.mutable_obs_stats();
  st->set_count(count / n);
  for (int d = 0; d < dim; ++d) {
    const double mu = mean[d] / n;
    st->set_mean(d, mu);
    st->set_var(d, std::max(0.0, second[d] / n - mu * mu));  // rounding can leave -1e-17
  }
  return out;
}

}  // namespace perch
