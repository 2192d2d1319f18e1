// SPDX-License-Identifier: GPL-3.0-or-later
// sphles_accuracy: run time against error (docs/accuracy.md).
//
//   build/bench/sphles_accuracy [--quick] [--only 2d|3d|peers|start|schemes|kolmogorov[,...]]
//   [--out DIR]
//                               [--reference-dir DIR] [--threads T] [--refine-2d K]
//                               [--refine-2d-side N] [--refine-3d-sides N[,N...]]
//                               [--wall-limit SECONDS] [--sides N[,N...]] [--config NAME[,...]]
//                               [--merge] [--list] [--trace] [--set dotted.key=value ...]
//
// Runs the configurations one after another, each on --threads OpenMP threads (default 1), and
// writes per study DIR/accuracy_<study>.csv (one row per run: parameters, single-thread wall and
// CPU seconds of the solver steps, errors), DIR/accuracy_history_<study>.csv (the recorded
// samples) and DIR/accuracy_run_<study>.json (load averages at start and end, total wall time).
// The CSV files are rewritten after every run, so an interrupted matrix keeps what finished.
// After the base matrix, the best configurations are refined: for each 2D Reynolds number the K
// configurations with the smallest e_v error at the largest base N are run at
// --refine-2d-side, and for 3D the configuration with the smallest resolved-energy misfit
// (SPEC §9; the dissipation misfit where no reference run covers the flow) at the largest base N
// is run at each of --refine-3d-sides.
//
// Extending a finished matrix: --sides replaces the base resolutions, --config keeps only the
// named configurations (as --list prints them), and --merge keeps the rows already in the output
// files whose labels this invocation does not run, so that, for example,
//   sphles_accuracy --only 3d --sides 64 --config "wendland_c4 D_K/dl=8 implicit" --merge
// adds one run to docs/accuracy_3d.csv. Merging takes an exclusive lock on DIR/.accuracy.lock
// and replaces each file by rename, so concurrent invocations into one DIR lose no rows.
#include <fcntl.h>
#include <omp.h>
#include <sys/file.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "bench/accuracy/accuracy.hpp"
#include "scene/document.hpp"
#include "sim/scene.hpp"

namespace {

namespace ac = sphles::accuracy;

int usage(const char* program) {
  std::cerr << "usage: " << program
            << " [--quick] [--only 2d|3d|peers|start|schemes|kolmogorov[,...]] [--out DIR] "
               "[--reference-dir DIR]\n"
               "       [--threads T] [--refine-2d K] [--refine-2d-side N]\n"
               "       [--refine-3d-sides N[,N...]] [--wall-limit SECONDS] [--sides N[,N...]]\n"
               "       [--config NAME[,NAME...]] [--merge] [--list] [--trace]\n"
               "       [--set dotted.key=value ...]  (applied to every scene; for testing)\n";
  return 2;
}

std::vector<std::string> split(const std::string& list) {
  std::vector<std::string> items;
  std::stringstream s(list);
  std::string item;
  while (std::getline(s, item, ','))
    if (!item.empty()) items.push_back(item);
  return items;
}

std::string load_average() {
  std::ifstream in("/proc/loadavg");
  std::string one, five, fifteen;
  in >> one >> five >> fifteen;
  return one + " " + five + " " + fifteen;
}

/// Refinement runs: the `count` configurations per study with the smallest `error` among
/// completed runs at the largest base resolution, at each of `sides`.
std::vector<ac::RunSpec> refinements(const std::vector<ac::RunResult>& results,
                                     double ac::RunResult::*error, std::size_t count,
                                     const std::vector<int>& sides) {
  std::map<std::string, std::vector<const ac::RunResult*>> by_study;
  for (const ac::RunResult& r : results) by_study[r.spec.study].push_back(&r);
  std::vector<ac::RunSpec> runs;
  for (auto& [study, list] : by_study) {
    int largest = 0;
    for (const ac::RunResult* r : list) largest = std::max(largest, r->particles_per_side);
    std::vector<const ac::RunResult*> candidates;
    for (const ac::RunResult* r : list)
      if (r->particles_per_side == largest && r->status == "completed" && std::isfinite(r->*error))
        candidates.push_back(r);
    std::sort(
        candidates.begin(), candidates.end(),
        [&](const ac::RunResult* a, const ac::RunResult* b) { return a->*error < b->*error; });
    for (std::size_t k = 0; k < std::min(count, candidates.size()); ++k)
      for (const int side : sides) runs.push_back(ac::with_resolution(candidates[k]->spec, side));
  }
  return runs;
}

/// What identifies a row of the output files: labels repeat across studies (both 2D Reynolds
/// numbers have "wendland_c2 D_K/dl=8 N=64").
std::string row_key(const std::string& study, const std::string& label) {
  return study + "|" + label;
}

/// The rows after the header of the CSV file `path` whose row_key (the study in the first field,
/// the label in field `label_column`) is not in `replaced`; none if the file does not exist. The
/// files hold no quoted commas.
std::vector<std::string> kept_rows(const std::string& path, std::size_t label_column,
                                   const std::set<std::string>& replaced) {
  std::vector<std::string> rows;
  std::ifstream in(path);
  std::string line;
  if (!std::getline(in, line)) return rows;  // missing or empty: nothing to keep
  while (std::getline(in, line)) {
    std::stringstream fields(line);
    std::string study, field;
    std::getline(fields, study, ',');
    for (std::size_t c = 1; c <= label_column && std::getline(fields, field, ','); ++c) {
    }
    if (!replaced.contains(row_key(study, field))) rows.push_back(line);
  }
  return rows;
}

/// Writes `text` to `path` by way of a temporary file and rename, so that no reader (and no
/// interrupted write) ever leaves half a file.
void replace_file(const std::string& path, const std::string& text) {
  const std::string temporary = path + ".tmp";
  {
    std::ofstream out(temporary, std::ios::trunc);
    out << text;
    out.close();
    if (!out) {
      std::cerr << "could not write " << temporary << '\n';
      std::exit(1);
    }
  }
  if (std::rename(temporary.c_str(), path.c_str()) != 0) {
    std::cerr << "could not rename " << temporary << " to " << path << '\n';
    std::exit(1);
  }
}

/// An exclusive flock on DIR/.accuracy.lock for the lifetime of the object (none when not
/// `enabled`): merging invocations that share an output directory read and replace its files
/// one at a time.
class DirectoryLock {
 public:
  DirectoryLock(const std::string& dir, bool enabled) {
    if (!enabled) return;
    const std::string path = dir + "/.accuracy.lock";
    fd_ = ::open(path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
    if (fd_ < 0 || ::flock(fd_, LOCK_EX) != 0) {
      std::cerr << "could not lock " << path << '\n';
      std::exit(1);
    }
  }
  ~DirectoryLock() {
    if (fd_ >= 0) ::close(fd_);  // closing releases the lock
  }
  DirectoryLock(const DirectoryLock&) = delete;
  DirectoryLock& operator=(const DirectoryLock&) = delete;

 private:
  int fd_ = -1;
};

/// The matrix of one study with the base resolutions replaced by `sides` (each configuration
/// once, at every side) and only the configurations named in `configs` kept (all if empty).
std::vector<ac::RunSpec> select_runs(const std::vector<ac::RunSpec>& matrix,
                                     const std::vector<int>& sides,
                                     const std::vector<std::string>& configs) {
  std::vector<ac::RunSpec> runs;
  std::set<std::string> seen;
  for (const ac::RunSpec& r : matrix) {
    if (!configs.empty() && std::find(configs.begin(), configs.end(), r.config) == configs.end())
      continue;
    if (sides.empty()) {
      runs.push_back(r);
    } else if (seen.insert(r.study + "|" + r.config).second) {
      for (const int side : sides) runs.push_back(ac::with_resolution(r, side));
    }
  }
  return runs;
}

/// The command line.
struct Options {
  bool quick = false, list_only = false, merge = false;
  std::vector<int> base_sides;       // empty: the matrix' own resolutions
  std::vector<std::string> configs;  // empty: every configuration
  std::string only = "2d,kolmogorov,3d", out_dir = ".";
  int threads = 1;
  int refine_2d = -1;  // -1: 1 in full mode, 0 with --quick
  int refine_2d_side = 256;
  std::vector<int> sides_3d;           // --refine-3d-sides: "40" in full mode, none with --quick
  std::vector<std::string> overrides;  // "dotted.key=value", applied to every scene
  ac::RunOptions run;
};

/// Reads the command line into `o`; false (after saying why, where there is more to say than the
/// usage) when it is not one.
bool parse_arguments(int argc, char** argv, Options& o) {
  std::string refine_3d_sides;  // empty: "40" in full mode, none with --quick
  bool refine_3d_set = false;
  o.run.reference_dir = SPHLES_SOURCE_DIR "/data/reference";
  for (int k = 1; k < argc; ++k) {
    const std::string arg = argv[k];
    auto value = [&]() -> std::string {
      if (k + 1 >= argc) {
        std::cerr << arg << " needs a value\n";
        std::exit(usage(argv[0]));
      }
      return argv[++k];
    };
    if (arg == "--quick") {
      o.quick = true;
    } else if (arg == "--only") {
      o.only = value();
    } else if (arg == "--out") {
      o.out_dir = value();
    } else if (arg == "--reference-dir") {
      o.run.reference_dir = value();
    } else if (arg == "--threads") {
      o.threads = std::atoi(value().c_str());
    } else if (arg == "--refine-2d") {
      o.refine_2d = std::atoi(value().c_str());
    } else if (arg == "--refine-2d-side") {
      o.refine_2d_side = std::atoi(value().c_str());
    } else if (arg == "--refine-3d-sides") {
      refine_3d_sides = value();
      refine_3d_set = true;
    } else if (arg == "--wall-limit") {
      o.run.wall_limit_seconds = std::atof(value().c_str());
    } else if (arg == "--set") {
      o.overrides.push_back(value());
    } else if (arg == "--sides") {
      for (const std::string& side : split(value())) {
        o.base_sides.push_back(std::atoi(side.c_str()));
        if (o.base_sides.back() < 2) {
          std::cerr << "--sides: '" << side << "' is not a resolution of at least 2\n";
          return false;
        }
      }
    } else if (arg == "--config") {
      o.configs = split(value());
    } else if (arg == "--merge") {
      o.merge = true;
    } else if (arg == "--list") {
      o.list_only = true;
    } else if (arg == "--trace") {
      o.run.trace = true;
    } else {
      return false;
    }
  }
  if (o.threads < 1) return false;
  if (o.refine_2d < 0) o.refine_2d = o.quick ? 0 : 1;
  if (!refine_3d_set) refine_3d_sides = o.quick ? "" : "40";
  for (const std::string& s : split(refine_3d_sides)) o.sides_3d.push_back(std::atoi(s.c_str()));
  return true;
}

/// The files one study writes into DIR.
struct StudyFiles {
  std::string summary, history, run;
};

StudyFiles study_files(const std::string& out_dir, const std::string& study) {
  return {out_dir + "/accuracy_" + study + ".csv", out_dir + "/accuracy_history_" + study + ".csv",
          out_dir + "/accuracy_run_" + study + ".json"};
}

/// Rewritten after every run. With --merge, the rows of runs this invocation does not make
/// stay (read under the directory lock, so concurrent invocations keep each other's rows).
void write_results(const Options& o, const StudyFiles& files,
                   const std::vector<ac::RunResult>& results) {
  const DirectoryLock lock(o.out_dir, o.merge);
  std::ostringstream summary, history;
  ac::write_summary_header(summary);
  ac::write_history_header(history);
  if (o.merge) {
    std::set<std::string> rerun;
    for (const ac::RunResult& r : results) rerun.insert(row_key(r.spec.study, r.spec.label));
    for (const std::string& row : kept_rows(files.summary, 2, rerun)) summary << row << '\n';
    for (const std::string& row : kept_rows(files.history, 1, rerun)) history << row << '\n';
  }
  for (const ac::RunResult& r : results) {
    ac::write_summary_row(summary, r);
    ac::write_history_rows(history, r);
  }
  replace_file(files.summary, summary.str());
  replace_file(files.history, history.str());
}

/// Runs `list` one after another, printing a line per run and rewriting the files after each.
void run_all(const std::vector<ac::RunSpec>& list, const char* phase, const std::string& study,
             const Options& o, const StudyFiles& files, std::vector<ac::RunResult>& results) {
  for (std::size_t k = 0; k < list.size(); ++k) {
    ac::RunResult r;
    try {
      r = ac::run_one(list[k], o.run);
    } catch (const std::exception& e) {
      std::cerr << list[k].label << ": " << e.what() << '\n';
      std::exit(1);
    }
    std::printf(
        "[%s %s %zu/%zu] %-14s %-40s %-10s t=%-6.4g steps=%-6llu wall=%7.1f s cpu=%7.1f s"
        "  E_res misfit=%.4g  e_v err=%.4g  v err=%.4g  eps misfit=%.4g  imbalance=%.4g"
        "  load %s\n",
        study.c_str(), phase, k + 1, list.size(), r.spec.study.c_str(), r.spec.label.c_str(),
        r.status.c_str(), r.time_reached, static_cast<unsigned long long>(r.steps), r.wall_seconds,
        r.cpu_seconds, r.resolved_misfit, r.case_name == "tgv3d" ? r.energy_misfit : r.energy_error,
        r.velocity_error_end, r.dissipation_misfit, r.budget_imbalance, load_average().c_str());
    std::fflush(stdout);
    results.push_back(r);
    write_results(o, files, results);
  }
}

/// DIR/accuracy_run_<study>.json: this invocation's record (load averages at start and end, total
/// wall time); with --merge, appended to the records of the earlier invocations.
void write_invocation_record(const std::string& study, const Options& o, const StudyFiles& files,
                             const std::vector<ac::RunResult>& results, double seconds,
                             const std::string& load_start) {
  nlohmann::json invocation = {{"study", study},
                               {"quick", o.quick},
                               {"threads_per_run", o.threads},
                               {"runs", results.size()},
                               {"labels", nlohmann::json::array()},
                               {"total_wall_seconds", seconds},
                               {"load_average_start", load_start},
                               {"load_average_end", load_average()}};
  for (const ac::RunResult& r : results)
    invocation["labels"].push_back(r.spec.study + " " + r.spec.label);
  nlohmann::json meta = invocation;
  const DirectoryLock lock(o.out_dir, o.merge);
  if (o.merge) {
    // One record per invocation that wrote into these files, the earlier ones first.
    nlohmann::json previous;
    std::ifstream in(files.run);
    if (in) previous = nlohmann::json::parse(in, nullptr, /*allow_exceptions=*/false);
    nlohmann::json records = nlohmann::json::array();
    if (previous.is_object() && previous.contains("invocations"))
      records = previous["invocations"];
    else if (previous.is_object())
      records.push_back(previous);
    records.push_back(invocation);
    meta = {{"study", study}, {"invocations", records}};
  }
  replace_file(files.run, meta.dump(2) + "\n");
}

/// One study: its base matrix, then its refinements; or with --list only its runs. The exit
/// status of the program when the study cannot run, else 0.
int run_study(const std::string& study, const Options& o, const char* program) {
  std::vector<ac::RunSpec> runs;
  try {
    runs = select_runs(ac::make_matrix(study, o.quick), o.base_sides, o.configs);
  } catch (const std::exception& e) {
    std::cerr << e.what() << '\n';
    return usage(program);
  }
  if (runs.empty()) {
    std::cerr << "--config: no configuration of study '" << study << "' is named (see --list)\n";
    return 2;
  }
  try {
    for (ac::RunSpec& r : runs)
      for (const std::string& assignment : o.overrides)
        sphles::scene::apply_override(r.scene, assignment);
  } catch (const std::exception& e) {
    std::cerr << e.what() << '\n';
    return 2;
  }
  if (o.list_only) {
    for (const ac::RunSpec& r : runs)
      std::cout << r.study << "  " << r.label << "  " << r.scene.dump() << '\n';
    return 0;
  }
  const StudyFiles files = study_files(o.out_dir, study);
  const std::string load_start = load_average();
  const auto study_start = std::chrono::steady_clock::now();
  std::vector<ac::RunResult> results;
  run_all(runs, "base", study, o, files, results);
  if (study == "2d" && o.refine_2d > 0)
    run_all(refinements(results, &ac::RunResult::energy_error,
                        static_cast<std::size_t>(o.refine_2d), {o.refine_2d_side}),
            "refine", study, o, files, results);
  if (study == "3d" && !o.sides_3d.empty()) {
    const bool resolved = std::any_of(results.begin(), results.end(), [](const auto& r) {
      return std::isfinite(r.resolved_misfit);
    });
    run_all(
        refinements(results,
                    resolved ? &ac::RunResult::resolved_misfit : &ac::RunResult::dissipation_misfit,
                    1, o.sides_3d),
        "refine", study, o, files, results);
  }
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - study_start).count();
  write_invocation_record(study, o, files, results, seconds, load_start);
  std::cout << "wrote " << files.summary << ", " << files.history << " (" << results.size()
            << " runs, " << seconds << " s wall)\n";
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  Options o;
  if (!parse_arguments(argc, argv, o)) return usage(argv[0]);
  omp_set_num_threads(o.threads);
  // Before any run: a result that cannot be written would be lost after hours of runs.
  if (!o.list_only) {
    std::error_code error;
    std::filesystem::create_directories(o.out_dir, error);
    if (error) {
      std::cerr << "--out: cannot create directory '" << o.out_dir << "': " << error.message()
                << '\n';
      return 1;
    }
  }
  for (const std::string& study : split(o.only))
    if (const int status = run_study(study, o, argv[0]); status != 0) return status;
  return 0;
}
