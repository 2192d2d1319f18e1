// SPDX-License-Identifier: GPL-3.0-or-later
#include "server/product_cache.hpp"

#include <algorithm>
#include <new>

#include "server/json_writer.hpp"

namespace sphles::server {

namespace {

/// Fewest bytes one number of an array takes: a digit and a comma.
constexpr std::size_t kMinBytesPerNumber = 2;
/// Generous room for the keys and scalars around the arrays of a product.
constexpr std::size_t kProductOverhead = 1024;

std::string step_text(const analysis::AnalysisFrame& frame) {
  return " of step " + std::to_string(frame.step);
}

}  // namespace

// Keys in alphabetical order, as nlohmann wrote them before (clients must not rely on it).
std::string spectrum_text(const analysis::AnalysisFrame& frame, std::size_t max_bytes) {
  const analysis::SpectrumProduct& p = frame.spectrum.value();
  JsonWriter w(max_bytes, "the spectrum" + step_text(frame));
  w.expect_at_least(kProductOverhead +
                    kMinBytesPerNumber * (p.spectrum.wavenumber.size() + p.spectrum.energy.size()));
  w.begin_object();
  w.key("delta_k").value(p.spectrum.delta_k);
  w.key("dissipation").value(p.dissipation);
  // -de_v/dt (5.4) of the run's time series at the frame's time (null while unknown).
  w.key("dissipation_energy").value(frame.energy_dissipation);
  w.key("dissipation_resolved").value(p.dissipation_resolved);
  // The third estimate of SPEC §5, ε_v = ν⟨ω²⟩ (4.6), when the scene computes vorticity.
  w.key("dissipation_vorticity");
  if (frame.vorticity)
    w.value(frame.vorticity->dissipation);
  else
    w.null();
  w.key("energy").array(std::span<const double>(p.spectrum.energy));
  w.key("k").array(std::span<const double>(p.spectrum.wavenumber));
  w.key("kernel_wavenumber").value(p.kernel_wavenumber);
  w.key("kinetic_energy_grid").value(p.kinetic_energy_grid);
  w.key("length_scale").value(p.length_scale);
  w.key("resolution_wavenumber").value(p.resolution_wavenumber);
  w.key("step").value(frame.step);
  w.key("time").value(frame.time);
  w.key("vorticity_estimate");
  if (frame.vorticity)
    w.value(analysis::vorticity_estimate_name(frame.vorticity->estimate));
  else
    w.null();
  w.end_object();
  return w.take();
}

std::string statistics_text(const analysis::AnalysisFrame& frame, std::size_t max_bytes) {
  const analysis::SubfilterStatisticsProduct& p = frame.subfilter.value();
  JsonWriter w(max_bytes, "the sub-filter statistics" + step_text(frame),
               "; lower analysis.histogram_bins");
  const std::size_t numbers =
      p.joint.counts.size() + (p.alignment ? p.alignment->counts.size() : 0);
  w.expect_at_least(kProductOverhead + kMinBytesPerNumber * numbers);
  w.begin_object();
  w.key("alignment");
  if (p.alignment) {
    const analysis::AngleHistogram& a = *p.alignment;
    w.begin_object();
    w.key("bins").value(a.bins);
    w.key("counts").array(std::span<const std::uint64_t>(a.counts));
    w.key("threshold").value(a.threshold);
    w.key("total").value(a.total);
    w.end_object();
  } else {
    w.null();
  }
  w.key("joint").begin_object();
  w.key("bins_x").value(p.joint.bins_x);
  w.key("bins_y").value(p.joint.bins_y);
  w.key("counts").array(std::span<const std::uint64_t>(p.joint.counts));
  w.key("total").value(p.joint.total);
  w.end_object();
  w.key("max_norm").value(p.max_norm);
  w.key("mean_norm").value(p.mean_norm);
  w.key("step").value(frame.step);
  w.key("time").value(frame.time);
  w.end_object();
  return w.take();
}

ProductCache::ProductCache(std::size_t max_bytes) : max_bytes_(max_bytes) {}

std::size_t ProductCache::entries() const {
  std::lock_guard lock(mutex_);
  return entries_.size();
}

std::shared_ptr<ProductCache::Slot> ProductCache::slot(
    const std::shared_ptr<const analysis::AnalysisFrame>& frame, Product product) {
  std::lock_guard lock(mutex_);
  std::erase_if(entries_, [](const Entry& e) { return e.frame.expired(); });
  const auto same = [&](const Entry& e) {
    return !e.frame.owner_before(frame) && !frame.owner_before(e.frame);
  };
  auto it = std::find_if(entries_.begin(), entries_.end(), same);
  if (it == entries_.end()) {
    if (entries_.size() >= kMaxFrames)
      entries_.erase(
          std::min_element(entries_.begin(), entries_.end(),
                           [](const Entry& a, const Entry& b) { return a.used < b.used; }));
    entries_.push_back(Entry{frame, {std::make_shared<Slot>(), std::make_shared<Slot>()}, 0});
    it = entries_.end() - 1;
  }
  it->used = ++clock_;
  return it->slots[static_cast<std::size_t>(product)];
}

std::shared_ptr<const std::string> ProductCache::get(
    const std::shared_ptr<const analysis::AnalysisFrame>& frame, Product product) {
  if (!frame) return nullptr;
  const bool has =
      product == Product::spectrum ? frame->spectrum.has_value() : frame->subfilter.has_value();
  if (!has) return nullptr;
  try {
    const std::shared_ptr<Slot> s = slot(frame, product);
    std::lock_guard lock(s->mutex);
    if (s->text) return s->text;
    if (s->error) throw *s->error;
    try {
      s->text = std::make_shared<const std::string>(product == Product::spectrum
                                                        ? spectrum_text(*frame, max_bytes_)
                                                        : statistics_text(*frame, max_bytes_));
    } catch (const ApiError& e) {
      s->error = e;
      throw;
    }
    return s->text;
  } catch (const std::bad_alloc&) {
    throw ApiError(503, std::string("out of memory while serialising the ") +
                            (product == Product::spectrum ? "spectrum" : "statistics") +
                            " of step " + std::to_string(frame->step) + "; try again later");
  }
}

}  // namespace sphles::server
