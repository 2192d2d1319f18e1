// SPDX-License-Identifier: GPL-3.0-or-later
// The neighbour loop of every SPH pass, written once (docs/performance.md, "The pair loop").
//
// A pass is an evaluator, a small struct of pure functions over plain data (sim/physics/), run
// by pair_pass: for each particle i of an owned range, in gather form, the evaluator's `pair`
// gives the contribution of every neighbour j inside the kernel support, the loop sums them,
// and the evaluator's `finish` writes the sums. The loop owns what is not physics:
//  - the pair geometry: x_ij = x_i - x_j through a geometry policy (PeriodicGeometry: the minimum
//    image of the periodic box, skipped for the particles at least H from its faces, where it is
//    the plain difference bit for bit; a halo geometry can take its place), r² and r;
//  - the support test 0 < r < H (r = 0 too for evaluators with coincident_pairs, the density);
//  - the threading: OpenMP over i, each i summed by one thread in a fixed order, so results do
//    not depend on the thread count;
//  - the vectorisation: OpenMP SIMD over j with a reduction in lanes (Summation::Lanes), or the
//    sum in list order (Summation::Ordered, SPHLES_SIMD=OFF); both are deterministic, and they
//    agree to round-off.
//
// An evaluator E provides
//   static constexpr int outputs;            doubles summed per particle
//   static constexpr bool coincident_pairs;  whether pairs at r = 0 (j != i) contribute
//   struct Own;                              what the pairs read of particle i
//   Own own(std::size_t i) const;
//   void pair(const Own&, const Pair<Dim>&, double (&out)[outputs]) const;
//   void finish(std::size_t i, const Own&, const double (&sum)[outputs]) const;
// `pair` is evaluated for every list entry and masked by the support test, so it must be
// finite-valued or harmless outside the support (kernel functions are zero there) and must not
// write anything itself.
//
// An evaluator that reduces by something other than a sum (the pairing statistics' two nearest
// distances) also provides
//   static constexpr double identity;   the value of a masked entry and the start of the reduction
//   static void accumulate(double (&acc)[outputs], const double (&c)[outputs]);
// and is reduced in list order.
#pragma once

#include <omp.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <concepts>
#include <cstddef>
#include <cstdint>
#include <span>
#include <tuple>
#include <type_traits>
#include <utility>
#include <vector>

#include "sim/neighbour_search.hpp"
#include "sim/particles.hpp"
#include "sim/select.hpp"

namespace sphles::sim {

/// One pair as an evaluator sees it: j, x_ij = x_i - x_j, r² = |x_ij|², r = |x_ij|.
template <int Dim>
struct Pair {
  std::uint32_t j;
  double dx[Dim];
  double r2;
  double r;
};

/// |x_ij|² summed from its first term, not 0.0 + dx₀²: the same bits (dx₀² ≥ 0), and one vector
/// addition fewer per pair in the vectorised loops (GCC keeps the addition of zero).
template <int Dim>
inline double squared_norm(const double (&dx)[Dim]) {
  double r2 = dx[0] * dx[0];
  for (int d = 1; d < Dim; ++d) r2 += dx[d] * dx[d];
  return r2;
}

/// x_ij = x_i - x_j as the plain difference of the stored positions: the geometry of the
/// particles PeriodicGeometry::interior finds far enough from the box's faces.
template <int Dim>
class DirectGeometry {
 public:
  explicit DirectGeometry(const double* const (&x)[Dim]) {
    for (int d = 0; d < Dim; ++d) x_[d] = x[d];
  }
  double separation(const double (&xi)[Dim], std::uint32_t j, double (&dx)[Dim]) const {
    for (int d = 0; d < Dim; ++d) dx[d] = xi[d] - x_[d][j];
    return squared_norm(dx);
  }

 private:
  const double* x_[Dim];
};

/// x_ij under the minimum image of the periodic box. The positions must lie in [0, L)
/// (wrap_periodic), as the solver keeps them.
template <int Dim>
class PeriodicGeometry {
 public:
  PeriodicGeometry(const PeriodicBox& box, const ParticleArrays& p) {
    for (int d = 0; d < Dim; ++d) {
      x_[d] = p.position[d].data();
      length_[d] = box.length[d];
      half_length_[d] = 0.5 * box.length[d];
    }
  }
  void position(std::size_t i, double (&xi)[Dim]) const {
    for (int d = 0; d < Dim; ++d) xi[d] = x_[d][i];
  }
  /// x_i - x_j (minimum image) into dx; returns |x_ij|².
  double separation(const double (&xi)[Dim], std::uint32_t j, double (&dx)[Dim]) const {
    for (int d = 0; d < Dim; ++d)
      dx[d] = minimum_image(xi[d] - x_[d][j], length_[d], half_length_[d]);
    return squared_norm(dx);
  }
  /// Whether x_i lies at least `reach` (times 1 + kInteriorMargin) from every face of the box.
  /// Then every particle j within `reach` of i along each axis sits at x_i - x_ij without a
  /// periodic shift, so the plain difference x_i - x_j is the minimum image bit for bit (no
  /// select of `separation` fires), and a particle beyond `reach` stays beyond it in the plain
  /// difference (which is never shorter than the minimum image). The pair loop then sums i's
  /// pairs with direct(): the same results, without the minimum image's compares and blends.
  bool interior(const double (&xi)[Dim], double reach) const {
    const double margin = reach * (1.0 + kInteriorMargin);
    bool inside = true;
    for (int d = 0; d < Dim; ++d) inside &= (xi[d] >= margin) & (xi[d] <= length_[d] - margin);
    return inside;
  }
  DirectGeometry<Dim> direct() const { return DirectGeometry<Dim>(x_); }

  /// Relative headroom of interior() over the reach, far above the rounding of x_i ± reach.
  static constexpr double kInteriorMargin = 1e-9;

 private:
  const double* x_[Dim];
  double length_[Dim];
  double half_length_[Dim];
};

/// A geometry with a shortcut for the particles far from the box's faces (PeriodicGeometry).
template <class Geometry, int Dim>
concept HasInteriorShortcut = requires(const Geometry& g, const double (&xi)[Dim]) {
  { g.interior(xi, 1.0) } -> std::convertible_to<bool>;
  g.direct();
};

/// The pairs inside the kernel support (0 < r < H) of every particle, in Verlet-list order: the
/// list the passes after the density pass of a force evaluation loop over (no support test, 40 %
/// fewer entries than the Verlet list). Built by density pass (compacting_pair_pass) at the
/// positions of that evaluation; valid until the positions change. Sized by its use: a
/// particle's entries sit together in a region of the array its thread reserved, an array of
/// about kMargin times the pairs of the last pass (not the Verlet list's size).
class InteractionList {
 public:
  /// Headroom of the entries' array over the last pass' pairs, so that the next passes' few per
  /// cent more pairs fit without growing it.
  static constexpr double kMargin = 1.1;
  /// Before the first pass, the array holds this share of the Verlet list's entries in 2D and
  /// 3D (the support's share of a list with the default skin 0.15 H is (1/1.15)^n: 0.76 and
  /// 0.66); a pass that needs more grows it once.
  static constexpr double kFirstShare2D = 0.8;
  static constexpr double kFirstShare3D = 0.7;
  /// The compaction's regions (compacting_pair_pass): each thread reserves about this many per
  /// pass, so that their unused tails stay a few per cent of the array, within these bounds.
  static constexpr std::size_t kRegionsPerThread = 16;
  static constexpr std::size_t kMinRegion = std::size_t{1} << 13;
  static constexpr std::size_t kMaxRegion = std::size_t{1} << 16;
  /// The entries a thread reserves at a time in an array of `capacity` entries filled by
  /// `threads` threads (more when one particle's candidates need more).
  static std::size_t region_size(std::size_t capacity, int threads) {
    return std::clamp<std::size_t>(
        capacity / (kRegionsPerThread * static_cast<std::size_t>(std::max(1, threads))), kMinRegion,
        kMaxRegion);
  }

  std::size_t num_particles() const { return count_.size(); }
  std::span<const std::uint32_t> of(std::size_t i) const {
    return {indices_.data() + offsets_[i], count_[i]};
  }
  /// Pairs in the list (Σ_i of(i).size()).
  std::size_t num_pairs() const;
  /// Entries the array holds (pairs and headroom).
  std::size_t capacity() const { return indices_.size(); }

  /// Makes room for the pairs of `verlet`'s particles in `dimension` dimensions (called by
  /// compacting_pair_pass): the array is kept, or sized from the last pass, or from `verlet`
  /// before the first.
  void prepare(const NeighbourList& verlet, int dimension) {
    const std::size_t n = verlet.num_particles();
    const std::size_t last = num_pairs();
    offsets_.assign(n, 0);
    count_.assign(n, 0);
    const auto wanted =
        static_cast<std::size_t>(last > 0 ? kMargin * static_cast<double>(last)
                                          : (dimension == 3 ? kFirstShare3D : kFirstShare2D) *
                                                static_cast<double>(verlet.num_entries()));
    if (indices_.size() < wanted || (last > 0 && indices_.size() > 2 * wanted)) {
      indices_.clear();  // nothing to keep: no copy
      indices_.resize(wanted);
    }
  }
  /// Particle i's `count` pairs are entries [at, at + count).
  void place(std::size_t i, std::size_t at, std::uint32_t count) {
    offsets_[i] = at;
    count_[i] = count;
  }
  std::uint32_t* entries(std::size_t at) { return indices_.data() + at; }
  /// Grows the array to `size` entries, keeping those written.
  void grow(std::size_t size) {
    if (indices_.size() < size) indices_.resize(size);
  }

 private:
  std::vector<std::size_t> offsets_;
  std::vector<std::uint32_t> indices_;
  std::vector<std::uint32_t> count_;
};

inline std::size_t InteractionList::num_pairs() const {
  std::size_t total = 0;
  for (const std::uint32_t c : count_) total += c;
  return total;
}

/// Several evaluators run as one pass over the same pairs: the pair geometry and the loads of
/// the list are shared, and each part's sums are the ones its own pass would form (output k of
/// part P is summed as part P sums it). finish calls the parts' finish in order, so a part may
/// add to what an earlier part wrote. The parts must agree on coincident_pairs and reduce by sums.
template <class... Parts>
class Fused {
 public:
  static constexpr int outputs = (Parts::outputs + ...);
  static constexpr bool coincident_pairs = (Parts::coincident_pairs || ...);
  static_assert(((Parts::coincident_pairs == coincident_pairs) && ...),
                "fused evaluators must agree on coincident pairs");
  struct Own {
    std::tuple<typename Parts::Own...> parts;
  };

  explicit Fused(Parts... parts) : parts_(std::move(parts)...) {}

  Own own(std::size_t i) const {
    return std::apply([i](const Parts&... p) { return Own{{p.own(i)...}}; }, parts_);
  }
  template <int Dim>
  void pair(const Own& o, const Pair<Dim>& q, double (&out)[outputs]) const {
    each([&]<std::size_t P>(const auto& part) {
      using Part = std::tuple_element_t<P, std::tuple<Parts...>>;
      double c[Part::outputs];
      part.pair(std::get<P>(o.parts), q, c);
      for (int k = 0; k < Part::outputs; ++k) out[offset<P>() + k] = c[k];
    });
  }
  void finish(std::size_t i, const Own& o, const double (&sum)[outputs]) const {
    each([&]<std::size_t P>(const auto& part) {
      using Part = std::tuple_element_t<P, std::tuple<Parts...>>;
      double s[Part::outputs];
      for (int k = 0; k < Part::outputs; ++k) s[k] = sum[offset<P>() + k];
      part.finish(i, std::get<P>(o.parts), s);
    });
  }

 private:
  /// The first output of part P.
  template <std::size_t P>
  static constexpr int offset() {
    constexpr int sizes[] = {Parts::outputs...};
    int first = 0;
    for (std::size_t k = 0; k < P; ++k) first += sizes[k];
    return first;
  }
  /// f.template operator()<P>(part P) for every part, in order.
  template <class F>
  void each(F&& f) const {
    [&]<std::size_t... P>(std::index_sequence<P...>) {
      (f.template operator()<P>(std::get<P>(parts_)), ...);
    }
    (std::index_sequence_for<Parts...>{});
  }

  std::tuple<Parts...> parts_;
};

/// How a particle's contributions are summed: in SIMD lanes (the vectorised loop) or in list
/// order. The build's default is Lanes, or Ordered with SPHLES_SIMD=OFF (SPHLES_NO_SIMD); a
/// caller may ask for either (the tests compare them).
enum class Summation { Lanes, Ordered };
#ifdef SPHLES_NO_SIMD
inline constexpr Summation kDefaultSummation = Summation::Ordered;
#else
inline constexpr Summation kDefaultSummation = Summation::Lanes;
#endif

namespace pair_loop_detail {

/// Evaluators with more outputs than this are summed in list order without vectors.
inline constexpr int kMaxVectorOutputs = 12;

/// Whether E reduces by its own accumulate (and identity) rather than by a sum.
template <class E>
concept CustomReduction = requires(double (&acc)[E::outputs], const double (&c)[E::outputs]) {
  { E::identity } -> std::convertible_to<double>;
  E::accumulate(acc, c);
};

template <class E>
constexpr double reduction_identity() {
  if constexpr (CustomReduction<E>)
    return E::identity;
  else
    return 0.0;
}

template <int O, int K>
inline void add(double& sum, const double (&c)[K]) {
  if constexpr (O < K) sum += c[O];
}

/// Σ over one particle's list of the evaluator's masked contributions (the loop body shared by
/// both passes). With Record, keep_out[k] is 0xFFFFFFFF when entry k lies inside the support,
/// 0 < r < H, else 0 (for the compaction). The mark is 32 bits wide like the list entries: the
/// vectoriser sizes the loop by its narrowest type, and a byte mark made it take 32 entries per
/// iteration (8 vectors of doubles) and leave up to 31 of a particle's entries to a scalar
/// remainder; with 32-bit marks it takes 8 and leaves at most 7 (docs/performance.md).
template <int Dim, Summation S, bool TestSupport, bool Record, class E, class Geometry>
inline void sum_pairs(const E& evaluator, const Geometry& geometry_ref,
                      const typename E::Own& own_ref, const double (&xi_ref)[Dim],
                      std::span<const std::uint32_t> js, double support2, double (&sum)[E::outputs],
                      std::uint32_t* keep_out) {
  constexpr int K = E::outputs;
  // Local copies: their members (array pointers, constants) are then known not to change in the
  // loop, so the loads become gathers from invariant bases and the loop vectorises.
  const E e = evaluator;
  const Geometry geometry = geometry_ref;
  const typename E::Own own = own_ref;
  double xi[Dim];
  for (int d = 0; d < Dim; ++d) xi[d] = xi_ref[d];
  const std::size_t count = js.size();
  const std::uint32_t* index = js.data();
  // The contribution of entry k, zero outside the support. The sums stay in the loops below
  // (a lambda capturing `sum` would bypass the SIMD reduction's private copies).
  const auto contribution = [&](std::size_t k, double(&c)[K]) {
    Pair<Dim> pair;
    pair.j = index[k];
    pair.r2 = geometry.separation(xi, pair.j, pair.dx);
    pair.r = std::sqrt(pair.r2);
    // Non-short-circuit & on the comparisons: && would be control flow, which GCC does not
    // vectorise.
    const bool in_support = pair.r2 < support2;
    const bool separate = pair.r2 > 0.0;
    if constexpr (Record) keep_out[k] = (in_support & separate) ? 0xFFFFFFFFu : 0u;
    e.pair(own, pair, c);
    const bool inside = !TestSupport || (in_support & (E::coincident_pairs || separate));
    for (int o = 0; o < K; ++o) c[o] = inside ? c[o] : reduction_identity<E>();
  };
  if constexpr (CustomReduction<E>) {
    for (std::size_t k = 0; k < count; ++k) {
      double c[K];
      contribution(k, c);
      E::accumulate(sum, c);
    }
  } else if constexpr (S == Summation::Lanes && K <= kMaxVectorOutputs) {
    // Named scalar accumulators: GCC 12 vectorises a reduction over scalars, not over an array
    // section (sum[:K] gave 2-wide code with scalar gathers). Those beyond K are never touched.
    double s0 = 0.0, s1 = 0.0, s2 = 0.0, s3 = 0.0, s4 = 0.0, s5 = 0.0, s6 = 0.0, s7 = 0.0, s8 = 0.0,
           s9 = 0.0, s10 = 0.0, s11 = 0.0;
#pragma omp simd reduction(+ : s0, s1, s2, s3, s4, s5, s6, s7, s8, s9, s10, s11)
    for (std::size_t k = 0; k < count; ++k) {
      double c[K];
      contribution(k, c);
      add<0>(s0, c), add<1>(s1, c), add<2>(s2, c), add<3>(s3, c), add<4>(s4, c), add<5>(s5, c);
      add<6>(s6, c), add<7>(s7, c), add<8>(s8, c), add<9>(s9, c), add<10>(s10, c), add<11>(s11, c);
    }
    const double lanes[kMaxVectorOutputs] = {s0, s1, s2, s3, s4, s5, s6, s7, s8, s9, s10, s11};
    for (int o = 0; o < K; ++o) sum[o] += lanes[o];
  } else {
    for (std::size_t k = 0; k < count; ++k) {
      double c[K];
      contribution(k, c);
      for (int o = 0; o < K; ++o) sum[o] += c[o];
    }
  }
}

}  // namespace pair_loop_detail

/// How this build sums a particle's pairs: "simd<W>-i32" (lanes of W doubles, the widest vector
/// the build targets and lets the vectoriser use, SPHLES_VECTOR_WIDTH; every loop's vector
/// length set by its 32-bit list entries, so that a vector of entries spans several vectors of
/// doubles) or "ordered" (list order, SPHLES_SIMD=OFF). Results of two builds agree bitwise only
/// when this agrees; the packing cache keys on it.
inline const char* pair_loop_summation() {
  if constexpr (kDefaultSummation == Summation::Ordered) return "ordered";
#if defined(__AVX512F__) && (!defined(SPHLES_VECTOR_BITS) || SPHLES_VECTOR_BITS >= 512)
  return "simd8-i32";
#elif defined(__AVX__)
  return "simd4-i32";
#else
  return "simd2-i32";
#endif
}

namespace pair_loop_detail {

/// One particle's whole pass: its own values, the sum over its pairs, the evaluator's finish.
/// With Record, keep[k] is 0xFFFFFFFF for a list entry k inside the support, else 0 (keep has
/// list.of(i).size()).
template <int Dim, Summation S, bool TestSupport, bool Record, class E, class Geometry>
inline void evaluate_particle(const E& e, const Geometry& geometry,
                              std::span<const std::uint32_t> js, std::size_t i,
                              double support_radius, std::uint32_t* keep) {
  const double support2 = support_radius * support_radius;
  const typename E::Own own = e.own(i);
  double xi[Dim];
  geometry.position(i, xi);
  double sum[E::outputs];
  for (double& s : sum) s = reduction_identity<E>();
  const auto sum_with = [&](const auto& g) {
    sum_pairs<Dim, S, TestSupport, Record>(e, g, own, xi, js, support2, sum, keep);
  };
  if constexpr (HasInteriorShortcut<Geometry, Dim>) {
    // Every pair that counts lies within the support radius (the interaction list's too).
    if (geometry.interior(xi, support_radius))
      sum_with(geometry.direct());
    else
      sum_with(geometry);
  } else {
    sum_with(geometry);
  }
  e.finish(i, own, sum);
}

}  // namespace pair_loop_detail

/// Runs evaluator e over the particles [begin, end) and the pairs of `list` (a NeighbourList,
/// tested against the support radius, or an InteractionList, whose pairs all lie inside it).
template <int Dim, Summation S = kDefaultSummation, class E, class List, class Geometry>
void pair_pass(const E& e, const Geometry& geometry, const List& list, double support_radius,
               std::size_t begin, std::size_t end) {
  constexpr bool kTestSupport = !std::is_same_v<List, InteractionList>;
  const auto first = static_cast<std::ptrdiff_t>(begin);
  const auto last = static_cast<std::ptrdiff_t>(end);
#pragma omp parallel for schedule(dynamic, 256)
  for (std::ptrdiff_t si = first; si < last; ++si) {
    const auto i = static_cast<std::size_t>(si);
    pair_loop_detail::evaluate_particle<Dim, S, kTestSupport, false>(e, geometry, list.of(i), i,
                                                                     support_radius, nullptr);
  }
}

/// pair_pass over a Verlet list that also records the pairs inside the support (0 < r < H) of
/// every particle in `interactions`, for the passes that follow at the same positions.
template <int Dim, Summation S = kDefaultSummation, class E, class Geometry>
void compacting_pair_pass(const E& e, const Geometry& geometry, const NeighbourList& list,
                          double support_radius, std::size_t begin, std::size_t end,
                          InteractionList& interactions) {
  interactions.prepare(list, Dim);
  // Each thread compacts its particles' pairs straight into a region of the list it reserved
  // by an atomic counter, and reserves the next region when a particle's candidates no longer
  // fit in the rest (append_selected may write all of them). A region that lies beyond the
  // array's end is filled in a buffer of the thread's and copied once the array has grown.
  // Where a particle's pairs lie depends on the threads' timing, what they are does not.
  const std::size_t capacity = interactions.capacity();
  const std::size_t region_size = InteractionList::region_size(capacity, omp_get_max_threads());
  std::atomic<std::size_t> next{0};
  struct Late {
    std::size_t at;
    std::vector<std::uint32_t> entries;
  };
  std::vector<Late> late;
  const auto first = static_cast<std::ptrdiff_t>(begin);
  const auto last = static_cast<std::ptrdiff_t>(end);
#pragma omp parallel
  {
    std::vector<std::uint32_t> keep;
    // The thread's region [at, limit) of the list, filled up to `used`; `buffer` holds it when
    // it lies beyond the array's end.
    std::size_t at = 0, used = 0, limit = 0;
    std::vector<std::uint32_t> buffer;
    const auto buffered = [&] { return limit > capacity; };
    const auto set_aside = [&] {
      if (!buffered()) return;
      buffer.resize(used - at);
#pragma omp critical(sphles_interaction_list_late)
      late.push_back({at, std::move(buffer)});
      buffer = {};
    };
#pragma omp for schedule(dynamic, 256)
    for (std::ptrdiff_t si = first; si < last; ++si) {
      const auto i = static_cast<std::size_t>(si);
      const std::span<const std::uint32_t> js = list.of(i);
      if (used + js.size() > limit) {
        set_aside();
        const std::size_t size = std::max(region_size, js.size());
        at = used = next.fetch_add(size, std::memory_order_relaxed);
        limit = at + size;
        if (buffered()) buffer.resize(size);
      }
      keep.resize(js.size());
      pair_loop_detail::evaluate_particle<Dim, S, true, true>(e, geometry, js, i, support_radius,
                                                              keep.data());
      std::uint32_t* out = buffered() ? buffer.data() + (used - at) : interactions.entries(used);
      const std::size_t kept = append_selected(js.data(), keep.data(), js.size(), out);
      interactions.place(i, used, static_cast<std::uint32_t>(kept));
      used += kept;
    }
    set_aside();
  }
  if (!late.empty()) {
    interactions.grow(
        static_cast<std::size_t>(InteractionList::kMargin * static_cast<double>(next.load())));
    for (const Late& l : late)
      std::copy(l.entries.begin(), l.entries.end(), interactions.entries(l.at));
  }
}

}  // namespace sphles::sim
