#include "covoxslam/integrators/esdf_integrator.h"

#include <cmath>
#include <string>

#include "covoxslam/core/error.h"

namespace covox::integrators {

struct EsdfIntegrator::Scratch {
  explicit Scratch(Device device) : buffers(device) {}
  EsdfScratchBuffers buffers;
};

EsdfIntegrator::EsdfIntegrator(const EsdfIntegratorConfig& config) : config_(config) {
  if (!(config.esdf_max_distance_m > 0.0f) || !std::isfinite(config.esdf_max_distance_m)) {
    throw Error("ESDF: esdf_max_distance_m must be positive, got " +
                std::to_string(config.esdf_max_distance_m));
  }
  if (!(config.site_distance_threshold_vox > 0.0f)) {
    throw Error("ESDF: site_distance_threshold_vox must be positive, got " +
                std::to_string(config.site_distance_threshold_vox));
  }
  if (!(config.min_weight > 0.0f)) {
    throw Error("ESDF: min_weight must be positive, got " + std::to_string(config.min_weight));
  }
}
EsdfIntegrator::~EsdfIntegrator() = default;
EsdfIntegrator::EsdfIntegrator(EsdfIntegrator&&) noexcept = default;
EsdfIntegrator& EsdfIntegrator::operator=(EsdfIntegrator&&) noexcept = default;

EsdfUpdateStats EsdfIntegrator::update(map::TsdfMap& map, const Stream& stream) {
  return run(map, false, stream);
}
EsdfUpdateStats EsdfIntegrator::update_all(map::TsdfMap& map, const Stream& stream) {
  return run(map, true, stream);
}

EsdfUpdateStats EsdfIntegrator::run(map::TsdfMap& map, bool all_blocks, const Stream& stream) {
  if (!scratch_ || scratch_->buffers.squared.device() != map.device()) {
    scratch_ = std::make_unique<Scratch>(map.device());
  }
  return dispatch(map.device(), [&](auto backend) {
    return esdf_update(backend, config_, map, all_blocks, scratch_->buffers, stream);
  });
}

}  // namespace covox::integrators
