// SPDX-License-Identifier: GPL-3.0-or-later
// The spectral reference's exchange between MPI ranks (spectral/slab_exchange.hpp): the slabs
// transposed by FFTW's MPI transpose (libfftw3-mpi; it moves values only, so the reference keeps
// its bits for any rank count), and the collectives by MPI.
#pragma once

#include <mpi.h>

#include <memory>

#include "spectral/slab_exchange.hpp"

namespace sphles::par {

class MpiSlabExchange final : public spectral::SlabExchange {
 public:
  /// The ranks of `comm` sharing an n^3 reference grid. Collective (FFTW plans the transpose);
  /// throws std::runtime_error when FFTW cannot plan it.
  MpiSlabExchange(MPI_Comm comm, int n);
  ~MpiSlabExchange() override;
  MpiSlabExchange(const MpiSlabExchange&) = delete;
  MpiSlabExchange& operator=(const MpiSlabExchange&) = delete;

  int ranks() const override { return ranks_; }
  int rank() const override { return rank_; }
  void transpose(std::complex<double>* in, std::complex<double>* out, bool forward) override;
  void sum(double* values, std::size_t count) override;
  double max(double value) override;
  void broadcast(double* values, std::size_t count) override;

 private:
  struct Plan;
  MPI_Comm comm_;
  int ranks_ = 1, rank_ = 0;
  std::unique_ptr<Plan> plan_;
};

}  // namespace sphles::par
