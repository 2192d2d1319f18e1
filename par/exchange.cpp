// SPDX-License-Identifier: GPL-3.0-or-later
#include "par/exchange.hpp"

#include <stdexcept>

#include "par/reduce.hpp"

namespace sphles::par {

namespace {

/// Adds the wall time of its lifetime to `seconds`.
class Timer {
 public:
  explicit Timer(double& seconds) : seconds_(seconds), start_(MPI_Wtime()) {}
  ~Timer() { seconds_ += MPI_Wtime() - start_; }
  Timer(const Timer&) = delete;
  Timer& operator=(const Timer&) = delete;

 private:
  double& seconds_;
  double start_;
};

}  // namespace

void MpiExchange::migrate(sim::ParticleArrays& p, std::span<std::vector<double>* const> carried) {
  const Timer timer(stats_.migrate_seconds);
  halo_.reset();  // its plan refers to the particles before migration
  stats_.migrated += par::migrate(d_, p, carried);
}

void MpiExchange::build_halo(sim::ParticleArrays& p) {
  const Timer timer(stats_.halo_build_seconds);
  halo_ = Halo::build(d_, p, HaloPositions::Wrapped);
  ++stats_.halo_builds;
  stats_.build_bytes += halo_->bytes_sent();
  stats_.halo_copies = halo_->size();
}

void MpiExchange::refresh(std::span<std::vector<double>* const> fields) const {
  if (!halo_) throw std::logic_error("halo refresh before the halo was built");
  const Timer timer(stats_.refresh_seconds);
  stats_.refresh_bytes += halo_->update(d_, fields);
}

double MpiExchange::max(double local) const {
  const Timer timer(stats_.reduce_seconds);
  double global = 0.0;
  MPI_Allreduce(&local, &global, 1, MPI_DOUBLE, MPI_MAX, d_.comm());
  return global;
}

bool MpiExchange::any(bool local) const {
  const Timer timer(stats_.reduce_seconds);
  int mine = local ? 1 : 0, all = 0;
  MPI_Allreduce(&mine, &all, 1, MPI_INT, MPI_MAX, d_.comm());
  return all != 0;
}

std::uint64_t MpiExchange::sum(std::uint64_t local) const {
  const Timer timer(stats_.reduce_seconds);
  unsigned long long mine = local, all = 0;
  MPI_Allreduce(&mine, &all, 1, MPI_UNSIGNED_LONG_LONG, MPI_SUM, d_.comm());
  return all;
}

void MpiExchange::sum(std::span<sim::ExactSum> partial) const {
  const Timer timer(stats_.reduce_seconds);
  allreduce(d_, partial);
}

}  // namespace sphles::par
