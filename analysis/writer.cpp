// SPDX-License-Identifier: GPL-3.0-or-later
#include "analysis/writer.hpp"

#include "io/image_data.hpp"

#include <charconv>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iterator>
#include <map>
#include <sstream>
#include <stdexcept>
#include <string_view>
#include <system_error>

namespace sphles::analysis {

namespace {

/// What a CSV cell holds for a value the frame does not have (numpy and pandas read it as NaN).
const std::string kNan = "nan";

/// The indices of a run directory the writer appends a row to per analysis time (docs/analysis.md).
const std::filesystem::path kSpectraIndex = "spectra/index.csv";
const std::filesystem::path kSlicesIndex = "slices/index.csv";
const std::filesystem::path kSnapshotsIndex = "snapshots/index.csv";
const std::filesystem::path kFieldsIndex = "fields/index.csv";
const std::filesystem::path kSummaryIndex = "stats/snapshots.csv";

/// Appends a line to a CSV index, writing the header when the file is new.
void append_line(const std::filesystem::path& path, const std::string& header,
                 const std::string& line) {
  const bool fresh = !std::filesystem::exists(path);
  std::ofstream out(path, std::ios::app);
  if (fresh) out << header << '\n';
  out << line << '\n';
  out.flush();
  if (!out) throw std::runtime_error("cannot append to '" + path.string() + "'");
}

std::string number(double x) {
  char buffer[32];
  std::snprintf(buffer, sizeof buffer, "%.17g", x);
  return buffer;
}

}  // namespace

void truncate_rows_after(const std::filesystem::path& path, double time) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return;
  const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  in.close();
  std::string kept;
  std::size_t begin = 0;
  for (bool header = true;; header = false) {
    const std::size_t end = text.find('\n', begin);
    if (end == std::string::npos) break;  // no line, or the last one cut short: dropped
    const std::string_view line(text.data() + begin, end - begin);
    double t = 0.0;
    const auto [next, error] = std::from_chars(line.data(), line.data() + line.size(), t);
    const bool timed = error == std::errc() && (next == line.data() + line.size() || *next == ',');
    if (header || (timed && t <= time)) {
      kept += line;
      kept += '\n';
    }
    begin = end + 1;
  }
  // Without a whole header line the file is removed, so that its writer starts it afresh.
  if (kept.empty())
    std::filesystem::remove(path);
  else
    replace_atomically(path, kept);
}

void truncate_run_files_after(const std::filesystem::path& run_directory, double time) {
  for (const std::filesystem::path& file :
       {std::filesystem::path("timeseries.csv"), std::filesystem::path("frames/index.csv"),
        kSpectraIndex, kSlicesIndex, kSnapshotsIndex, kFieldsIndex, kSummaryIndex})
    truncate_rows_after(run_directory / file, time);
}

void replace_atomically(const std::filesystem::path& path, const std::string& content) {
  const std::filesystem::path temporary = path.string() + ".tmp";
  {
    std::ofstream out(temporary, std::ios::binary | std::ios::trunc);
    out.write(content.data(), static_cast<std::streamsize>(content.size()));
    out.flush();
    if (!out) throw std::runtime_error("cannot write '" + temporary.string() + "'");
  }
  std::filesystem::rename(temporary, path);
}

std::vector<std::map<std::string, std::string>> read_index(const std::filesystem::path& path) {
  std::vector<std::map<std::string, std::string>> rows;
  std::ifstream in(path);
  std::string line;
  if (!std::getline(in, line)) return rows;
  const auto split = [](const std::string& text) {
    std::vector<std::string> cells;
    std::stringstream row(text);
    for (std::string cell; std::getline(row, cell, ',');) cells.push_back(cell);
    return cells;
  };
  const std::vector<std::string> header = split(line);
  while (std::getline(in, line)) {
    const std::vector<std::string> cells = split(line);
    std::map<std::string, std::string> row;
    for (std::size_t k = 0; k < header.size() && k < cells.size(); ++k) row[header[k]] = cells[k];
    rows.push_back(std::move(row));
  }
  return rows;
}

double index_number(const std::map<std::string, std::string>& row, const std::string& column,
                    const std::filesystem::path& file) {
  const auto it = row.find(column);
  if (it == row.end() || it->second.empty())
    throw std::runtime_error("'" + file.string() + "': a row has no '" + column + "'");
  try {
    std::size_t used = 0;
    const double value = std::stod(it->second, &used);
    if (used == it->second.size()) return value;
  } catch (const std::exception&) {
  }
  throw std::runtime_error("'" + file.string() + "': '" + column + "' is not a number: '" +
                           it->second + "'");
}

void write_npy(const std::filesystem::path& path, std::span<const double> values, std::size_t rows,
               std::size_t columns) {
  if (values.size() != rows * columns) throw std::invalid_argument("write_npy: shape mismatch");
  std::string header = "{'descr': '<f8', 'fortran_order': False, 'shape': (" +
                       std::to_string(rows) + ", " + std::to_string(columns) + "), }";
  // Magic (6) + version (2) + header length (2) + header + '\n' is a multiple of 64.
  const std::size_t unpadded = 10 + header.size() + 1;
  header.append((64 - unpadded % 64) % 64, ' ');
  header += '\n';
  std::string content("\x93NUMPY\x01\x00", 8);
  const auto length = static_cast<std::uint16_t>(header.size());
  content += static_cast<char>(length & 0xff);
  content += static_cast<char>(length >> 8);
  content += header;
  content.append(reinterpret_cast<const char*>(values.data()), values.size() * sizeof(double));
  replace_atomically(path, content);
}

RunDirectoryWriter::RunDirectoryWriter(std::filesystem::path directory,
                                       io::SnapshotMetadata metadata)
    : directory_(std::move(directory)), metadata_(std::move(metadata)) {
  for (const char* sub : {"spectra", "slices", "stats", "snapshots", "fields"}) {
    std::error_code ec;
    std::filesystem::create_directories(directory_ / sub, ec);
    if (ec)
      throw std::runtime_error("cannot create '" + (directory_ / sub).string() +
                               "': " + ec.message());
  }
}

ParticleFileTarget RunDirectoryWriter::particle_target() const {
  return {directory_ / "snapshots", metadata_};
}

std::string RunDirectoryWriter::last_error() const {
  std::lock_guard lock(mutex_);
  return last_error_;
}

void RunDirectoryWriter::write(const AnalysisFrame& frame) {
  try {
    write_or_throw(frame);
  } catch (const std::exception& e) {
    std::lock_guard lock(mutex_);
    last_error_ = e.what();
  }
}

void RunDirectoryWriter::write_or_throw(const AnalysisFrame& frame) {
  if (frame.spectrum) write_spectrum(frame, *frame.spectrum);
  for (const SliceProduct& slice : frame.slices) write_slice(frame, slice);
  if (frame.subfilter) write_statistics(frame, *frame.subfilter);
  if (frame.particles) write_particles(frame, *frame.particles);
  if (frame.fields) write_fields(frame, *frame.fields);
  write_summary(frame);
}

/// spectra/E_t{t}.csv and its line in spectra/index.csv.
void RunDirectoryWriter::write_spectrum(const AnalysisFrame& frame, const SpectrumProduct& s) {
  std::ostringstream csv;
  csv << "k,E,k_Lc,E_over_ev_Lc\n";
  const double e_v = s.kinetic_energy_grid;
  for (std::size_t p = 0; p < s.spectrum.wavenumber.size(); ++p) {
    const double k = s.spectrum.wavenumber[p], e = s.spectrum.energy[p];
    csv << number(k) << ',' << number(e) << ',' << number(k * s.length_scale) << ','
        << (e_v > 0.0 ? number(e / (e_v * s.length_scale)) : kNan) << '\n';
  }
  const std::string file = timed_file_name("E", frame.time, ".csv");
  replace_atomically(directory_ / "spectra" / file, csv.str());
  append_line(directory_ / kSpectraIndex,
              "t,step,file,e_v_grid,dissipation_spectral,dissipation_spectral_resolved,k_kernel,"
              "k_resolution,delta_k,L_c",
              number(frame.time) + ',' + std::to_string(frame.step) + ',' + file + ',' +
                  number(e_v) + ',' + number(s.dissipation) + ',' + number(s.dissipation_resolved) +
                  ',' + number(s.kernel_wavenumber) + ',' + number(s.resolution_wavenumber) + ',' +
                  number(s.spectrum.delta_k) + ',' + number(s.length_scale));
}

/// slices/{field}_t{t}.npy and .vti, slices/index.csv and the field's ParaView collection.
void RunDirectoryWriter::write_slice(const AnalysisFrame& frame, const SliceProduct& slice) {
  const std::string field(slice_field_name(slice.field));
  const std::string file = timed_file_name(field, frame.time, ".npy");
  const std::string vti = timed_file_name(field, frame.time, ".vti");
  write_npy(directory_ / "slices" / file, slice.values, static_cast<std::size_t>(slice.height),
            static_cast<std::size_t>(slice.width));
  // The same plane as VTK image data: one point thick along the normal, so that values[iu +
  // width iv] (u < v) is VTK's x-fastest point order.
  io::ImageData image;
  image.dimensions[static_cast<std::size_t>(slice.axis_u)] = slice.width;
  image.dimensions[static_cast<std::size_t>(slice.axis_v)] = slice.height;
  image.origin[static_cast<std::size_t>(slice.normal_axis)] = slice.position;
  image.spacing = {slice.spacing, slice.spacing, slice.spacing};
  image.time = frame.time;
  image.arrays.push_back({field, slice.units, 1, slice.values});
  io::write_vti(directory_ / "slices" / vti, image, metadata_.code_version);
  double lo = slice.values.empty() ? 0.0 : slice.values.front(), hi = lo;
  for (const double v : slice.values) {
    lo = std::min(lo, v);
    hi = std::max(hi, v);
  }
  static constexpr const char* kAxis[] = {"x", "y", "z"};
  const auto index = directory_ / kSlicesIndex;
  append_line(index,
              "t,step,field,units,normal_axis,position,axis_u,axis_v,width,height,spacing,min,"
              "max,file,vti",
              number(frame.time) + ',' + std::to_string(frame.step) + ',' + field + ',' +
                  slice.units + ',' + kAxis[slice.normal_axis] + ',' + number(slice.position) +
                  ',' + kAxis[slice.axis_u] + ',' + kAxis[slice.axis_v] + ',' +
                  std::to_string(slice.width) + ',' + std::to_string(slice.height) + ',' +
                  number(slice.spacing) + ',' + number(lo) + ',' + number(hi) + ',' + file + ',' +
                  vti);
  // One ParaView collection per field over every slice in the index (earlier runs of this
  // directory included).
  std::vector<io::CollectionEntry> series;
  for (const auto& row : read_index(index))
    if (row.contains("vti") && row.at("field") == field)
      series.push_back({std::stod(row.at("t")), row.at("vti")});
  io::write_pvd(directory_ / "slices" / (field + ".pvd"), series);
}

/// stats/joint_tau_omega2_t{t}.csv and, in 2D, stats/alignment_t{t}.csv.
void RunDirectoryWriter::write_statistics(const AnalysisFrame& frame,
                                          const SubfilterStatisticsProduct& s) {
  std::ostringstream joint;
  joint << "tau_lo,tau_hi,omega2_lo,omega2_hi,count\n";
  const Histogram2D& h = s.joint;
  for (int by = 0; by < h.bins_y; ++by)
    for (int bx = 0; bx < h.bins_x; ++bx) {
      const std::uint64_t c = h.counts[static_cast<std::size_t>(bx + h.bins_x * by)];
      if (c == 0) continue;
      joint << number(static_cast<double>(bx) / h.bins_x) << ','
            << number(static_cast<double>(bx + 1) / h.bins_x) << ','
            << number(static_cast<double>(by) / h.bins_y) << ','
            << number(static_cast<double>(by + 1) / h.bins_y) << ',' << c << '\n';
    }
  replace_atomically(directory_ / "stats" / timed_file_name("joint_tau_omega2", frame.time, ".csv"),
                     joint.str());
  if (s.alignment) {
    std::ostringstream polar;
    polar << "gamma_lo,gamma_hi,count,fraction\n";
    const AngleHistogram& a = *s.alignment;
    const double width = 0.5 * M_PI / a.bins;
    for (int b = 0; b < a.bins; ++b) {
      const std::uint64_t c = a.counts[static_cast<std::size_t>(b)];
      polar << number(b * width) << ',' << number((b + 1) * width) << ',' << c << ','
            << (a.total ? number(static_cast<double>(c) / a.total) : kNan) << '\n';
    }
    replace_atomically(directory_ / "stats" / timed_file_name("alignment", frame.time, ".csv"),
                       polar.str());
  }
}

/// snapshots/particles_t{t}.h5 (unless the ranks wrote it), snapshots/index.csv and the XDMF
/// series.
void RunDirectoryWriter::write_particles(const AnalysisFrame& frame, const ParticlesProduct& p) {
  std::vector<io::ParticleField> fields;
  std::string names;
  for (const ParticleFieldProduct& f : p.fields) {
    fields.push_back({std::string(slice_field_name(f.field)), f.units, f.values});
    names += (names.empty() ? "" : ";") + std::string(slice_field_name(f.field));
  }
  // The ranks of a distributed run wrote the file themselves (make_snapshot), here.
  const std::string file = p.file.empty() ? timed_file_name("particles", frame.time, ".h5")
                                          : std::filesystem::path(p.file).filename().string();
  if (p.file.empty())
    io::write_particle_snapshot(directory_ / "snapshots" / file, p.snapshot->particles, frame.time,
                                frame.step, fields, metadata_);
  const auto index = directory_ / kSnapshotsIndex;
  append_line(index, "t,step,file,particles,fields",
              number(frame.time) + ',' + std::to_string(frame.step) + ',' + file + ',' +
                  std::to_string(p.file.empty() ? p.snapshot->size() : p.count) + ',' + names);
  // The XDMF series lists every snapshot in the index (including those of earlier runs of
  // this directory, e.g. before a restart).
  std::vector<io::SnapshotEntry> entries;
  for (const auto& row : read_index(index)) {
    if (!row.contains("particles")) continue;
    io::SnapshotEntry e;
    e.time = std::stod(row.at("t"));
    e.file = row.at("file");
    e.count = std::stoul(row.at("particles"));
    if (row.contains("fields")) {
      std::stringstream list(row.at("fields"));
      for (std::string name; std::getline(list, name, ';');) e.scalars.push_back(name);
    }
    entries.push_back(e);
  }
  io::write_xdmf_series(directory_ / "snapshots" / "particles.xdmf", entries);
}

/// fields/fields_t{t}.vti, fields/index.csv and fields/fields.pvd.
void RunDirectoryWriter::write_fields(const AnalysisFrame& frame, const GridFieldsProduct& f) {
  const std::size_t points = f.grid.size();
  io::ImageData image;
  for (int d = 0; d < f.grid.dimension; ++d)
    image.dimensions[static_cast<std::size_t>(d)] = f.grid.points_per_side;
  const double h = f.grid.spacing();
  image.spacing = {h, h, h};
  image.time = frame.time;
  std::string names;
  if (f.velocity) {
    io::ImageArray v{"velocity", "m/s", 3, std::vector<double>(3 * points, 0.0)};
    for (int d = 0; d < f.grid.dimension; ++d)
      for (std::size_t n = 0; n < points; ++n)
        v.values[3 * n + static_cast<std::size_t>(d)] =
            f.velocity->component[static_cast<std::size_t>(d)][n];
    image.arrays.push_back(std::move(v));
    names = "velocity";
  }
  for (const GridScalarField& g : f.scalars) {
    const std::string name(slice_field_name(g.field));
    image.arrays.push_back({name, g.units, 1, g.values});
    names += (names.empty() ? "" : ";") + name;
  }
  const std::string file = timed_file_name("fields", frame.time, ".vti");
  io::write_vti(directory_ / "fields" / file, image, metadata_.code_version);
  const auto index = directory_ / kFieldsIndex;
  append_line(index, "t,step,file,points_per_side,spacing,arrays",
              number(frame.time) + ',' + std::to_string(frame.step) + ',' + file + ',' +
                  std::to_string(f.grid.points_per_side) + ',' + number(h) + ',' + names);
  std::vector<io::CollectionEntry> series;
  for (const auto& row : read_index(index))
    if (row.contains("file")) series.push_back({std::stod(row.at("t")), row.at("file")});
  io::write_pvd(directory_ / "fields" / "fields.pvd", series);
}

/// One line of stats/snapshots.csv per analysed snapshot, whatever its products.
void RunDirectoryWriter::write_summary(const AnalysisFrame& frame) {
  append_line(directory_ / kSummaryIndex,
              "t,step,e_v,e_v_grid,mean_omega2,dissipation_vorticity,dissipation_spectral,"
              "tau_sfs_max,tau_sfs_mean,analysis_seconds,dropped_snapshots,"
              "dissipation_spectral_resolved,dissipation_energy",
              number(frame.time) + ',' + std::to_string(frame.step) + ',' +
                  number(frame.kinetic_energy) + ',' +
                  (frame.grid_kinetic_energy ? number(*frame.grid_kinetic_energy)
                   : frame.spectrum          ? number(frame.spectrum->kinetic_energy_grid)
                                             : kNan) +
                  ',' + (frame.vorticity ? number(frame.vorticity->mean_vorticity_squared) : kNan) +
                  ',' + (frame.vorticity ? number(frame.vorticity->dissipation) : kNan) + ',' +
                  (frame.spectrum ? number(frame.spectrum->dissipation) : kNan) + ',' +
                  (frame.subfilter ? number(frame.subfilter->max_norm) : kNan) + ',' +
                  (frame.subfilter ? number(frame.subfilter->mean_norm) : kNan) + ',' +
                  number(frame.total_seconds) + ',' + std::to_string(frame.dropped_snapshots) +
                  ',' + (frame.spectrum ? number(frame.spectrum->dissipation_resolved) : kNan) +
                  ',' + number(frame.energy_dissipation));
}

}  // namespace sphles::analysis
