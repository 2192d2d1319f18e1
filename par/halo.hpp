// SPDX-License-Identifier: GPL-3.0-or-later
// Halo exchange and migration of particles between the ranks of a Decomposition.
//
// A rank's ParticleArrays hold its owned particles at [0, owned) and, after Halo::build, the
// halo behind them: copies of every particle (of other ranks, or this rank's own periodic
// images) whose position lies within the halo width of the sub-box, in this rank's frame
// (shifted by the box length across the periodic boundary), so the pair loop needs no minimum
// image. The exchange is staged: along x, then y (forwarding the x halo), then z, so edge and
// corner particles arrive in two or three hops, each rank talking to its 2 (4, 6) face
// neighbours only. A rank alone along an axis exchanges with itself.
//
// Determinism: what a rank sends, and the order it appends what it receives, depend only on the
// particles' order and positions, never on timing.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <stdexcept>
#include <vector>

#include "par/decomposition.hpp"
#include "sim/particles.hpp"

namespace sphles::par {

/// A particle moved further than one sub-box along an axis between two migrations.
class MigrationError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// Where the halo copies sit.
enum class HaloPositions {
  /// In this rank's frame, shifted by the box length across the periodic boundary: every copy
  /// an image of its own, for a geometry without minimum image.
  Shifted,
  /// At the particles' own positions in [0, L), one copy per particle, for the minimum-image
  /// geometry of one process (sim::PeriodicGeometry, sim::VerletNeighbourSearch): pair
  /// distances are then bitwise those of one process. Axes this rank is alone along are
  /// skipped (the minimum image finds those neighbours in its own particles).
  Wrapped,
};

/// The halo of one rank and the plan to refresh it.
class Halo {
 public:
  /// Appends the halo of width d.halo_width() to p, whose particles must all be owned (inside
  /// this rank's sub-box): positions, every field of ParticleArrays::double_fields() and the
  /// ids. Collective over d.comm(); throws std::invalid_argument on every rank when a particle
  /// of some rank lies outside its sub-box.
  static Halo build(const Decomposition& d, sim::ParticleArrays& p,
                    HaloPositions positions = HaloPositions::Shifted);

  /// Sends the current values of `fields` along the same stages, overwriting their halo entries:
  /// the exchange after a pass whose results the next pass reads of neighbours (V and p after
  /// the density pass). Each field holds w values per particle of p (w = its size / p.size(),
  /// particle-major). Positions are sent unshifted, so they may be among the fields of a
  /// HaloPositions::Wrapped halo only. Collective over d.comm().
  /// Returns the bytes this rank sent.
  std::size_t update(const Decomposition& d, std::span<std::vector<double>* const> fields) const;

  /// Particles owned by this rank: the halo is [owned(), owned() + size()).
  std::size_t owned() const { return owned_; }
  std::size_t size() const { return received_; }
  /// Bytes this rank sent in build (positions, fields and ids).
  std::size_t bytes_sent() const { return bytes_sent_; }

 private:
  struct Stage {
    int axis = 0;
    int to = 0;
    int from = 0;
    int tag = 0;
    double shift = 0.0;  // added to the sent positions along `axis`
    std::vector<std::uint32_t> send;
    std::size_t receive_begin = 0;
    std::size_t receive_count = 0;
    /// HaloPositions::Wrapped drops a second copy of a particle already here: then `kept` holds
    /// the numbers of the received records that were appended, in order.
    bool deduplicated = false;
    std::vector<std::uint32_t> kept;
  };
  std::vector<Stage> stages_;
  std::size_t owned_ = 0;
  std::size_t received_ = 0;
  std::size_t bytes_sent_ = 0;
};

/// Sends every particle of p (owned particles only, no halo) that has left this rank's sub-box to
/// the rank that owns it now, positions wrapped into the box. Staged along x, y, z like the halo,
/// so a particle may move at most one sub-box along each axis between two calls (a list rebuild
/// comes long before). Kept particles stay in their order, received ones follow; `carried`
/// (per-particle arrays of p.size() values kept alongside p) move with their particles. Returns
/// the number of particles this rank sent. Collective over d.comm(); throws MigrationError (on
/// every rank) when a particle moved further.
std::size_t migrate(const Decomposition& d, sim::ParticleArrays& p,
                    std::span<std::vector<double>* const> carried = {});

}  // namespace sphles::par
