// SPDX-License-Identifier: GPL-3.0-or-later
// An FFTW r2c plan with its own input and output buffers, made and destroyed under the planner
// lock (analysis::fftw_planner_lock): the one-process spectrum's (spectrum.cpp) and par/'s
// distributed one's (par/spectrum.cpp). Buffers come from FFTW's allocator (always SIMD-aligned,
// so the planner cannot pick different codelets from one call to the next because of alignment).
#pragma once

#include <fftw3.h>

#include <cstddef>
#include <mutex>
#include <new>

namespace sphles::analysis {

/// FFTW's planner is not thread-safe: every plan made or destroyed in the program (here, in
/// spectral/ and in par/) is made under this lock.
std::unique_lock<std::mutex> fftw_planner_lock();

class R2cPlan {
 public:
  /// `real_count` doubles of input, `complex_count` complex values of output, and the plan
  /// make_plan(input, output) returns on them; throws std::bad_alloc when any of them is missing.
  template <class MakePlan>
  R2cPlan(std::size_t real_count, std::size_t complex_count, MakePlan&& make_plan) {
    const std::unique_lock<std::mutex> lock = fftw_planner_lock();
    input_ = fftw_alloc_real(real_count);
    output_ = fftw_alloc_complex(complex_count);
    if (input_ != nullptr && output_ != nullptr) plan_ = make_plan(input_, output_);
    if (plan_ == nullptr) {
      release();
      throw std::bad_alloc();
    }
  }
  R2cPlan(const R2cPlan&) = delete;
  R2cPlan& operator=(const R2cPlan&) = delete;
  ~R2cPlan() {
    const std::unique_lock<std::mutex> lock = fftw_planner_lock();
    release();
  }

  double* input() const { return input_; }
  const fftw_complex* output() const { return output_; }
  /// fftw_execute is thread-safe: no lock.
  void execute() const { fftw_execute(plan_); }

 private:
  void release() {  // the caller holds the planner lock
    if (plan_ != nullptr) fftw_destroy_plan(plan_);
    fftw_free(output_);
    fftw_free(input_);
    plan_ = nullptr;
    output_ = nullptr;
    input_ = nullptr;
  }

  double* input_ = nullptr;
  fftw_complex* output_ = nullptr;
  fftw_plan plan_ = nullptr;
};

}  // namespace sphles::analysis
