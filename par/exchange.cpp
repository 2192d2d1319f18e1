#include "par/exchange.hpp"

#include <stdexcept>

#include "par/reduce.hpp"

namespace sphles::par {

void MpiExchange::migrate(sim::ParticleArrays& p, std::span<std::vector<double>* const> carried) {
  halo_.reset();  // its plan refers to the particles before migration
  migrated_ += par::migrate(d_, p, carried);
}

void MpiExchange::build_halo(sim::ParticleArrays& p) {
  halo_ = Halo::build(d_, p, HaloPositions::Wrapped);
}

void MpiExchange::refresh(std::span<std::vector<double>* const> fields) const {
  if (!halo_) throw std::logic_error("halo refresh before the halo was built");
  halo_->update(d_, fields);
}

double MpiExchange::max(double local) const {
  double global = 0.0;
  MPI_Allreduce(&local, &global, 1, MPI_DOUBLE, MPI_MAX, d_.comm());
  return global;
}

bool MpiExchange::any(bool local) const {
  int mine = local ? 1 : 0, all = 0;
  MPI_Allreduce(&mine, &all, 1, MPI_INT, MPI_MAX, d_.comm());
  return all != 0;
}

std::uint64_t MpiExchange::sum(std::uint64_t local) const {
  unsigned long long mine = local, all = 0;
  MPI_Allreduce(&mine, &all, 1, MPI_UNSIGNED_LONG_LONG, MPI_SUM, d_.comm());
  return all;
}

void MpiExchange::sum(std::span<sim::ExactSum> partial) const {
  allreduce(d_, partial);
}

}  // namespace sphles::par
