// SPDX-License-Identifier: GPL-3.0-or-later
// The Eigen modules sphles uses, included once behind a warning guard.
//
// GCC 12 with -march=native on an AVX-512 machine reports a false -Wmaybe-uninitialized inside
// its own avx512fintrin.h when Eigen's vectorised kernels are inlined. The diagnostic is located
// in the intrinsics header, which Eigen includes first, so the guard must enclose that first
// include: every file includes Eigen through this header only.
#pragma once

#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <Eigen/Eigenvalues>
#pragma GCC diagnostic pop
