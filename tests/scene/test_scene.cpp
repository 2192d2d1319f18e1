// SPDX-License-Identifier: GPL-3.0-or-later
// Scene files: defaults, overrides and the documented errors, in-process and through the real
// sphles program (exit code 2 and a message naming the field).
#include <gtest/gtest.h>
#include <algorithm>
#include <sstream>

#include <sys/wait.h>
#include <array>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <numbers>

#include "scene/document.hpp"
#include "scene/presets.hpp"
#include "scene/schema.hpp"
#include "scene_test_support.hpp"
#include "sim/initial_conditions.hpp"
#include "sim/kernels.hpp"
#include "sim/scene.hpp"
#include "sim/scene_warnings.hpp"

namespace sphles::sim {

using scene::apply_override;
using scene::dotted_keys;
using scene::parse_scene;
using scene::scene_to_json;
namespace {

using nlohmann::json;

TEST(Scene, DefaultsFollowSpecForTaylorGreen3D) {
  const Scene s = parse_scene(json::object());
  EXPECT_EQ(s.case_type, CaseType::TaylorGreen3D);
  EXPECT_EQ(s.dimension(), 3);
  EXPECT_EQ(s.kernel, KernelType::WendlandC4);
  EXPECT_DOUBLE_EQ(s.kernel_diameter_over_spacing, 8.0);
  EXPECT_DOUBLE_EQ(s.fluid.sound_speed, 5.0);          // Ma = 0.2
  EXPECT_DOUBLE_EQ(s.fluid.reference_pressure, 6.25);  // ρ c²/4
  EXPECT_DOUBLE_EQ(s.fluid.dynamic_viscosity, 1e-4);   // Re = 10^4
  EXPECT_DOUBLE_EQ(s.end_time, 15.0);
  EXPECT_NEAR(s.box_length(), 2.0 * M_PI, 1e-15);
}

TEST(Scene, RoundTripThroughJson) {
  json doc = {{"case", "tgv2d"},
              {"particles_per_side", 40},
              {"kernel", {{"type", "quintic_spline"}, {"diameter_over_spacing", 6}}},
              {"flow", {{"uniform_velocity", {0.5, -1.0}}}},
              {"time", {{"fixed_step", 1e-3}}},
              {"blow_up", {{"energy_factor", 4}, {"reference_energy", 0.3}}}};
  const Scene s = parse_scene(doc);
  const json written = scene_to_json(s);
  EXPECT_EQ(scene_to_json(parse_scene(written)), written);
  // The blow-up thresholds reach the solver unchanged (the rest keeps its default).
  const SolverConfig solver = make_solver_config(s);
  EXPECT_DOUBLE_EQ(solver.blow_up.energy_factor, 4.0);
  EXPECT_DOUBLE_EQ(solver.blow_up.reference_energy, 0.3);
  EXPECT_DOUBLE_EQ(solver.blow_up.reference_mach, BlowUpThresholds{}.reference_mach);
  EXPECT_EQ(written["kernel"]["type"], "quintic_spline");
  EXPECT_EQ(written["flow"]["uniform_velocity"], json({0.5, -1.0}));
  EXPECT_EQ(s.num_particles(), 1600u);
}

TEST(Scene, OverridesUseDottedPathsAndJsonValues) {
  json doc = json::object();
  apply_override(doc, "kernel.type=wendland_c6");
  apply_override(doc, "particles_per_side=24");
  apply_override(doc, "packing.enabled=false");
  apply_override(doc, "flow.uniform_velocity=[0,0,3.14]");
  const Scene s = parse_scene(doc);
  EXPECT_EQ(s.kernel, KernelType::WendlandC6);
  EXPECT_EQ(s.particles_per_side, 24);
  EXPECT_FALSE(s.packing.enabled);
  EXPECT_DOUBLE_EQ(s.uniform_velocity[2], 3.14);
  EXPECT_THROW(apply_override(doc, "no_equals_sign"), SceneError);
  EXPECT_THROW(apply_override(doc, "kernel..type=x"), SceneError);
  EXPECT_THROW(apply_override(doc, "particles_per_side.x=1"), SceneError);
  EXPECT_THROW(apply_override(doc, "kernel.=x"), SceneError);
  EXPECT_THROW(apply_override(doc, ".kernel=x"), SceneError);
  try {
    apply_override(doc, "packing.enabled.deep=1");
    ADD_FAILURE() << "a key below a boolean was accepted";
  } catch (const SceneError& e) {
    EXPECT_NE(std::string(e.what()).find("'packing.enabled' is not an object"), std::string::npos)
        << e.what();
  }
}

TEST(Scene, DottedKeysSplitEveryDot) {
  using Keys = std::vector<std::string>;
  EXPECT_EQ(dotted_keys(""), Keys{});
  EXPECT_EQ(dotted_keys("kernel"), Keys{"kernel"});
  EXPECT_EQ(dotted_keys("analysis.slice.fields"), (Keys{"analysis", "slice", "fields"}));
  EXPECT_EQ(dotted_keys("a..b"), (Keys{"a", "", "b"}));
  EXPECT_EQ(dotted_keys("a."), (Keys{"a", ""}));
  EXPECT_EQ(dotted_keys(".a"), (Keys{"", "a"}));
}

/// The fields of a scene's warnings (sim/scene_warnings.hpp), and the first message.
std::pair<std::vector<std::string>, std::string> warnings_of(const json& document) {
  std::vector<std::string> fields;
  std::string first;
  for (const SceneWarning& w : scene_warnings(parse_scene(document))) {
    fields.push_back(w.field);
    if (first.empty()) first = w.message;
  }
  return {fields, first};
}

// A scene that runs but whose answer means nothing says so: kolmogorov2d scaled down to 48² has
// D_K = 8Δl = 7 mm, wider than half the forcing wavelength (6 mm): e_v collapsed to 4 % of the
// laminar value with no word in run.log or the dashboard.
TEST(SceneWarnings, AKernelWiderThanTheCasesScaleAMachNumberAndAViscousStep) {
  using Fields = std::vector<std::string>;
  auto [fields, message] = warnings_of({{"preset", "kolmogorov2d"}, {"particles_per_side", 48}});
  EXPECT_EQ(fields, Fields{"particles_per_side"});
  EXPECT_NE(message.find("below the forcing's wavenumber k_y 1047.2 1/m"), std::string::npos)
      << message;
  EXPECT_NE(message.find("'particles_per_side' >= 112 resolves it"), std::string::npos) << message;
  EXPECT_TRUE(warnings_of({{"preset", "kolmogorov2d"}, {"particles_per_side", 112}}).first.empty());
  // The 3D TGV at 16³: k_SPH = 1 below the vortices' √3 (accuracy.md: no resolved energy).
  std::tie(fields, message) = warnings_of({{"case", "tgv3d"}, {"particles_per_side", 16}});
  EXPECT_EQ(fields, Fields{"particles_per_side"});
  EXPECT_NE(message.find(">= 28 resolves it"), std::string::npos) << message;
  EXPECT_TRUE(warnings_of({{"case", "tgv3d"}, {"particles_per_side", 28}}).first.empty());
  // Ma = 4 / 10 beyond 0.3; a viscous limit that sets the step.
  std::tie(fields, message) =
      warnings_of({{"case", "tgv2d"}, {"flow", {{"velocity_amplitude", 4}}}});
  EXPECT_EQ(fields, Fields{"fluid.sound_speed"});
  EXPECT_NE(message.find("v/c_s = 0.4 exceeds 0.3"), std::string::npos) << message;
  std::tie(fields, message) =
      warnings_of({{"case", "tgv2d"}, {"fluid", {{"dynamic_viscosity", 50.0}}}});
  EXPECT_EQ(fields, Fields{"fluid.dynamic_viscosity"});
  EXPECT_NE(message.find("the viscous limit sets the time step"), std::string::npos) << message;
  // Every shipped scene and preset at its own size means something.
  for (const auto& entry : std::filesystem::directory_iterator(SPHLES_SOURCE_DIR "/scenes")) {
    json document = scene::read_scene_file(entry.path());
    for (const char* section : {"analysis", "render", "reference"}) document.erase(section);
    EXPECT_TRUE(warnings_of(document).first.empty()) << entry.path();
  }
  for (const std::string& preset : scene::preset_names())
    EXPECT_TRUE(warnings_of({{"preset", preset}}).first.empty()) << preset;
}

struct BadScene {
  json document;
  std::string expected;  // substring of the error
};

class BadSceneTest : public ::testing::TestWithParam<BadScene> {};

TEST_P(BadSceneTest, ErrorNamesFieldAndReason) {
  const std::string error = testing::scene_error(GetParam().document);
  ASSERT_FALSE(error.empty()) << "scene was accepted: " << GetParam().document.dump();
  EXPECT_NE(error.find(GetParam().expected), std::string::npos) << error;
}

INSTANTIATE_TEST_SUITE_P(
    Errors, BadSceneTest,
    ::testing::Values(
        BadScene{{{"kernel", {{"typ", "wendland_c4"}}}}, "unknown key 'kernel.typ'"},
        BadScene{{{"colour", 1}}, "unknown key 'colour'"},
        BadScene{{{"particles_per_side", "32"}},
                 "'particles_per_side' must be an integer, got string"},
        BadScene{{{"particles_per_side", 32.5}}, "'particles_per_side' must be an integer"},
        BadScene{{{"particles_per_side", 1}}, "'particles_per_side' must be in [2, 4096], got 1"},
        BadScene{{{"fluid", {{"sound_speed", -1}}}}, "'fluid.sound_speed' must be > 0, got -1"},
        BadScene{{{"fluid", {{"dynamic_viscosity", "x"}}}},
                 "'fluid.dynamic_viscosity' must be a number, got string"},
        BadScene{{{"fluid", 3}}, "'fluid' must be an object, got number"},
        BadScene{{{"kernel", {{"type", "gauss"}}}},
                 "'kernel.type' must be one of wendland_c2, wendland_c4, wendland_c6, "
                 "quintic_spline, got 'gauss'"},
        BadScene{{{"case", "channel"}},
                 "'case' must be one of tgv3d, tgv2d, kolmogorov2d, got 'channel'"},
        BadScene{{{"time", {{"cfl_acoustic", 3}}}}, "'time.cfl_acoustic' must be in (0, 2], got 3"},
        BadScene{{{"blow_up", {{"energy_factor", 1}}}},
                 "'blow_up.energy_factor' must be > 1, got 1"},
        BadScene{{{"blow_up", {{"reference_mach", -0.1}}}},
                 "'blow_up.reference_mach' must be >= 0, got -0.1"},
        BadScene{{{"packing", {{"enabled", 1}}}},
                 "'packing.enabled' must be true or false, got number"},
        BadScene{{{"case", "tgv2d"}, {"flow", {{"uniform_velocity", {1, 2, 3}}}}},
                 "'flow.uniform_velocity' must be an array of 2 numbers"},
        BadScene{{{"fluid", {{"reference_pressure", 1e308}}}},
                 "'fluid.reference_pressure' must be at most 10 rho_ref c_s^2 = 250 Pa, got "
                 "1e+308"},
        BadScene{{{"case", "tgv2d"}, {"fluid", {{"reference_pressure", 1000.001}}}},
                 "'fluid.reference_pressure' must be at most 10 rho_ref c_s^2 = 1000 Pa"},
        BadScene{{{"particles_per_side", 6}, {"kernel", {{"diameter_over_spacing", 8}}}},
                 "box length 6.28319 m is smaller than the kernel diameter D_K = 8.37758 m"}),
    [](const ::testing::TestParamInfo<BadScene>& info) {
      return "case" + std::to_string(info.index);
    });

// --- the real program --------------------------------------------------------------------

struct ProcessResult {
  int exit_code;
  std::string output;
};

/// The output (stdout and stderr) and exit code of a shell command line.
ProcessResult run_shell(const std::string& command_line) {
  const std::string command = command_line + " 2>&1";
  FILE* pipe = popen(command.c_str(), "r");
  if (!pipe) return {-1, "popen failed"};
  std::string output;
  std::array<char, 4096> buffer;
  while (std::fgets(buffer.data(), buffer.size(), pipe)) output += buffer.data();
  const int status = pclose(pipe);
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, output};
}

ProcessResult run_sphles(const std::string& arguments) {
  return run_shell(std::string(SPHLES_BINARY) + " " + arguments);
}

class CliTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = std::filesystem::temp_directory_path() /
           ("sphles_cli_" + std::to_string(::getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    std::filesystem::create_directories(dir_);
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }
  std::string write(const std::string& name, const std::string& text) {
    std::ofstream(dir_ / name) << text;
    return (dir_ / name).string();
  }
  std::filesystem::path dir_;
};

TEST_F(CliTest, BadSceneExitsWithCodeTwoAndNamesField) {
  const auto bad = write("bad.json", R"({"fluid": {"sound_speed": -5}})");
  const ProcessResult r = run_sphles("run " + bad + " --out " + (dir_ / "out").string());
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("'fluid.sound_speed' must be > 0"), std::string::npos) << r.output;
  EXPECT_FALSE(std::filesystem::exists(dir_ / "out")) << "a rejected scene must not create output";
}

TEST_F(CliTest, InvalidJsonMissingFileAndBadOptions) {
  const auto broken = write("broken.json", "{\"case\": ");
  ProcessResult r = run_sphles("run " + broken);
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.output.find("is not valid JSON"), std::string::npos) << r.output;
  r = run_sphles("run " + (dir_ / "missing.json").string());
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.output.find("cannot open file"), std::string::npos) << r.output;
  const auto good = write("good.json", "{}");
  r = run_sphles("run " + good + " --threads zero");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.output.find("--threads"), std::string::npos) << r.output;
  r = run_sphles("run " + good + " --threads 0");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.output.find("--threads"), std::string::npos) << r.output;
  r = run_sphles("run " + good + " --set kernel.diameter=4");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.output.find("unknown key 'kernel.diameter'"), std::string::npos) << r.output;
  r = run_sphles("frobnicate");
  EXPECT_EQ(r.exit_code, 2);
  r = run_sphles("");
  EXPECT_EQ(r.exit_code, 2) << r.output;
  r = run_sphles("run " + good + " --no-such-option");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.output.find("--no-such-option"), std::string::npos) << r.output;
}

// Every command prints its own help with exit code 0, naming its options.
TEST_F(CliTest, EveryCommandHasItsOwnHelp) {
  const std::pair<const char*, const char*> commands[] = {
      {"run", "--restart"},         {"serve", "--launcher"},        {"estimate", "--json"},
      {"inspect", "CHECKPOINT.h5"}, {"calibrate", "--target-urms"}, {"presets", "presets"}};
  for (const auto& [command, option] : commands) {
    const ProcessResult r = run_sphles(std::string(command) + " --help");
    EXPECT_EQ(r.exit_code, 0) << command << ": " << r.output;
    EXPECT_NE(r.output.find(option), std::string::npos) << command << ": " << r.output;
  }
  ProcessResult r = run_sphles("--help");
  EXPECT_EQ(r.exit_code, 0) << r.output;
  for (const char* command : {"run", "serve", "presets", "estimate", "inspect", "calibrate"})
    EXPECT_NE(r.output.find(command), std::string::npos) << command << ": " << r.output;
  EXPECT_EQ(r.output.find("worker"), std::string::npos) << "the job's worker is not for users";
  // --version and `version` name the program, its licence and the absence of warranty, as GNU
  // programs do (LICENSE).
  for (const char* version : {"--version", "version"}) {
    r = run_sphles(version);
    EXPECT_EQ(r.exit_code, 0) << version;
    EXPECT_EQ(r.output.rfind("sphles " SPHLES_VERSION "\n", 0), 0u) << version << ": " << r.output;
    EXPECT_NE(r.output.find("\nLicense GPL-3.0-or-later: GNU GPL version 3 or later "
                            "<https://gnu.org/licenses/gpl.html>"),
              std::string::npos)
        << version << ": " << r.output;
    EXPECT_NE(r.output.find("There is NO WARRANTY"), std::string::npos)
        << version << ": " << r.output;
  }
}

// --log-level: validated by name; it sets what the console and run.log receive.
TEST_F(CliTest, LogLevelIsValidatedAndSetsWhatIsLogged) {
  ProcessResult r = run_sphles("serve --log-level loud");
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("--log-level: loud not in {trace,debug,info,warn,error,off}"),
            std::string::npos)
      << r.output;
  // 24²: the smallest 2D TGV whose kernel resolves its vortices (no scene warning).
  const auto tiny = write("tiny.json", R"({"case": "tgv2d", "particles_per_side": 24,
      "packing": {"enabled": false}, "time": {"end": 0.02}})");
  r = run_sphles("run " + tiny + " --threads 1 --out " + (dir_ / "info").string());
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("state: running -> finished"), std::string::npos) << r.output;
  std::ifstream info_log(dir_ / "info" / "run.log");
  const std::string info((std::istreambuf_iterator<char>(info_log)), {});
  EXPECT_NE(info.find(" info  state: running -> finished\n"), std::string::npos) << info;
  EXPECT_NE(info.find(" info  sphles run: finished, outputs in "), std::string::npos) << info;
  r = run_sphles("run " + tiny + " --threads 1 --log-level warn --out " + (dir_ / "warn").string());
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_EQ(r.output, "") << "nothing at warn or above happened";
  std::ifstream warn_log(dir_ / "warn" / "run.log");
  const std::string quiet((std::istreambuf_iterator<char>(warn_log)), {});
  EXPECT_NE(quiet.find(" info  state: running -> finished\n"), std::string::npos)
      << "the run's record keeps info: " << quiet;
}

// run --dry-run: particles, neighbours, memory and the measured time per step and to the end,
// nothing written; a run that cannot fit in this machine's memory is refused, dry or not.
TEST_F(CliTest, DryRunEstimatesAndWritesNothing) {
  const auto tiny = write("tiny.json", R"({"case": "tgv2d", "particles_per_side": 16,
      "packing": {"enabled": false}, "time": {"end": 0.5}})");
  const auto out = dir_ / "dry";
  ProcessResult r = run_sphles("run " + tiny + " --dry-run --threads 1 --out " + out.string());
  EXPECT_EQ(r.exit_code, 0) << r.output;
  for (const char* line :
       {"particles            256 (", "memory at the peak", "time per step",
        "on 1 threads (measured: 10 steps of 16^2 particles", "time to the end", "to t = 0.5 s"})
    EXPECT_NE(r.output.find(line), std::string::npos) << line << "\n" << r.output;
  EXPECT_FALSE(std::filesystem::exists(out)) << "a dry run writes nothing";
  r = run_sphles("run tgv3d-case1 --set particles_per_side=2048 --dry-run --out " + out.string());
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("the run does NOT fit"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("this machine has"), std::string::npos) << r.output;
  EXPECT_EQ(r.output.find("time per step"), std::string::npos) << "not timed: " << r.output;
  r = run_sphles("run tgv3d-case1 --set particles_per_side=2048 --out " + out.string());
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("sphles run: the run needs an estimated"), std::string::npos) << r.output;
  EXPECT_FALSE(std::filesystem::exists(out));
  r = run_sphles("run --dry-run --restart " + out.string());
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("--dry-run estimates a new run"), std::string::npos) << r.output;
  r = run_sphles("estimate " + tiny + " --time --json --threads 1");
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("\"seconds_per_step\""), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("\"fits_machine_memory\": true"), std::string::npos) << r.output;
}

/// The output and exit code of a bash script (written to `file`).
ProcessResult run_bash(const std::string& script, const std::filesystem::path& file) {
  std::ofstream(file) << script;
  return run_shell("bash " + file.string());
}

// The manual page and the bash completion are generated from the same declarations that parse
// the command line: every option a command's --help lists is in the manual, groff reads the
// page without a warning, and the completion completes commands, options and preset names.
TEST_F(CliTest, ManualPageAndCompletionFollowTheCommandLine) {
  const ProcessResult man = run_sphles("docs man");
  ASSERT_EQ(man.exit_code, 0) << man.output;
  for (const char* command : {"run", "serve", "presets", "estimate", "inspect", "calibrate"}) {
    EXPECT_NE(man.output.find(std::string(".SS \"sphles ") + command), std::string::npos)
        << command;
    const ProcessResult help = run_sphles(std::string(command) + " --help");
    std::size_t at = 0;
    int options = 0;
    while ((at = help.output.find("  --", at)) != std::string::npos) {
      const std::size_t end = help.output.find_first_of(" \n,=", at + 2);
      const std::string name = help.output.substr(at + 2, end - at - 2);
      at = end;
      if (name == "--help") continue;
      ++options;
      std::string escaped;  // roff writes '-' as "\-"
      for (const char c : name) escaped += c == '-' ? std::string("\\-") : std::string(1, c);
      EXPECT_NE(man.output.find(escaped), std::string::npos) << command << " " << name;
    }
    if (std::string(command) != "presets" && std::string(command) != "inspect") {
      EXPECT_GT(options, 0) << command << ": no options found in its help";
    }
  }
  EXPECT_EQ(man.output.find("worker"), std::string::npos) << "the worker is not for users";
  const std::string page = write("sphles.1", man.output);
  const ProcessResult groff = run_bash("groff -man -Tutf8 -ww -z " + page + "\n", dir_ / "g.sh");
  EXPECT_EQ(groff.exit_code, 0) << groff.output;
  EXPECT_EQ(groff.output, "") << "groff warnings: " << groff.output;

  const ProcessResult completion = run_sphles("docs bash-completion");
  ASSERT_EQ(completion.exit_code, 0) << completion.output;
  const std::string script = write("sphles.bash", completion.output);
  const ProcessResult r =
      run_bash("source " + script +
                   "\n"
                   "complete_words() { COMP_WORDS=(\"$@\"); COMP_CWORD=$(( $# - 1 )); _sphles; "
                   "echo \"[${COMPREPLY[*]}]\"; }\n"
                   "complete_words sphles ser\n"
                   "complete_words sphles run --thr\n"
                   "complete_words sphles serve --launch\n"
                   "complete_words sphles run kolmogorov\n"
                   "complete_words sphles estimate --js\n"
                   "complete_words sphles wor\n"
                   "complete_words sphles run tgv2d --log-level d\n"
                   "complete_words sphles run tgv2d --set kernel.ty\n",
               dir_ / "c.sh");
  EXPECT_EQ(r.exit_code, 0) << r.output;
  // --log-level completes its levels (it offered preset names), --set the scene's keys.
  EXPECT_EQ(r.output,
            "[serve]\n[--threads]\n[--launcher]\n[kolmogorov2d]\n[--json]\n[]\n[debug]\n"
            "[kernel.type=]\n");
}

// A typo in a scene key or a preset name is answered with what it was probably meant to be.
TEST_F(CliTest, TyposGetASuggestion) {
  const auto good = write("good.json", "{}");
  ProcessResult r = run_sphles("run " + good + " --set kernel.typ=quintic_spline");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.output.find("unknown key 'kernel.typ'; did you mean 'kernel.type'?"),
            std::string::npos)
      << r.output;
  r = run_sphles("run tgv3d-case99");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.output.find("'tgv3d-case99' is neither a scene file nor a preset; did you mean "
                          "'tgv3d-case9'?"),
            std::string::npos)
      << r.output;
  r = run_sphles("estimate kolmogorov");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.output.find("did you mean 'kolmogorov2d'?"), std::string::npos) << r.output;
  // A mistyped command is named, with the command it is nearest to.
  r = run_sphles("rn tgv2d");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.output.find("unknown command 'rn' (did you mean 'run'?)"), std::string::npos)
      << r.output;
  r = run_sphles("xyzzyq");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.output.find("unknown command 'xyzzyq'; 'sphles help' lists the commands"),
            std::string::npos)
      << r.output;
  // Far from every key: no suggestion.
  r = run_sphles("run " + good + " --set zzzzzzzz=1");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(r.output.find("did you mean"), std::string::npos) << r.output;
}

// An --out that cannot be created is an I/O failure (exit 1), not a usage error.
TEST_F(CliTest, AnUnwritableOutIsAnIoFailure) {
  const auto good = write("good.json", R"({"case": "tgv2d", "particles_per_side": 16})");
  const auto blocker = write("blocker", "a file where a directory would go");
  const ProcessResult r =
      run_sphles("run " + good + " --out " + (std::filesystem::path(blocker) / "out").string());
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find("cannot set up the run directory"), std::string::npos) << r.output;
}

TEST_F(CliTest, SmallRunWritesSceneAndTimeSeries) {
  const auto scene = write("tiny.json", R"({"case": "tgv2d", "particles_per_side": 16,
      "kernel": {"diameter_over_spacing": 4}, "time": {"end": 0.05},
      "packing": {"enabled": false}})");
  const auto out = dir_ / "out";
  const ProcessResult r = run_sphles("run " + scene + " --threads 2 --out " + out.string());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("steps/s"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("ETA"), std::string::npos) << r.output;
  std::ifstream csv(out / "timeseries.csv");
  std::string header, line, last;
  std::getline(csv, header);
  EXPECT_EQ(header, "t,step,dt,e_v,dissipation,max_density_deviation,max_speed");
  int rows = 0;
  while (std::getline(csv, line)) {
    last = line;
    ++rows;
  }
  EXPECT_GT(rows, 2);
  EXPECT_DOUBLE_EQ(std::stod(last.substr(0, last.find(','))), 0.05);  // ends exactly at t_end
  const json written = json::parse(std::ifstream(out / "scene.json"));
  EXPECT_EQ(written["particles_per_side"], 16);
  EXPECT_EQ(written["case"], "tgv2d");
  // No analysis requested: no analysis directories.
  EXPECT_FALSE(std::filesystem::exists(out / "spectra"));
}

TEST_F(CliTest, RunWithAnalysisWritesProductsAtTheCadence) {
  const auto scene = write("analysed.json", R"({"case": "tgv2d", "particles_per_side": 16,
      "kernel": {"diameter_over_spacing": 4}, "time": {"end": 0.1},
      "packing": {"enabled": false},
      "analysis": {"every": 0.05, "products": ["spectrum", "slices", "sfs_stats"]}})");
  const auto out = dir_ / "out";
  const ProcessResult r = run_sphles("run " + scene + " --out " + out.string());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  // Snapshots at t = 0, 0.05, 0.1. This tiny run outpaces analysis, and still every requested
  // time is written: the delivery is lossless.
  unsigned published = 0, analysed = 0, dropped = 0;
  const auto line = r.output.find("analysis: ");
  ASSERT_NE(line, std::string::npos) << r.output;
  ASSERT_EQ(std::sscanf(r.output.c_str() + line,
                        "analysis: %u snapshots published, %u analysed, %u dropped", &published,
                        &analysed, &dropped),
            3);
  EXPECT_EQ(published, 3u);
  EXPECT_EQ(analysed, 3u);
  EXPECT_EQ(dropped, 0u);
  for (const char* time : {"0.0000", "0.0500", "0.1000"})
    EXPECT_TRUE(std::filesystem::exists(out / "spectra" / ("E_t" + std::string(time) + ".csv")))
        << time;
  EXPECT_TRUE(std::filesystem::exists(out / "spectra" / "E_t0.1000.csv"));
  EXPECT_TRUE(std::filesystem::exists(out / "slices" / "omega2_t0.1000.npy"));
  EXPECT_TRUE(std::filesystem::exists(out / "slices" / "tau_sfs_t0.1000.npy"));
  EXPECT_TRUE(std::filesystem::exists(out / "stats" / "alignment_t0.1000.csv"));
  const json written = json::parse(std::ifstream(out / "scene.json"));
  EXPECT_EQ(written["analysis"]["every"], 0.05);
  EXPECT_FALSE(std::filesystem::exists(out / "stats" / "vorticity"));
  // run.json and the end summary list what was written, at exactly the requested times.
  const json record = json::parse(std::ifstream(out / "run.json"));
  const json& outputs = record["outputs"];
  const json times = json::array({0.0, 0.05, 0.1});
  EXPECT_EQ(outputs["spectra"]["count"], 3) << outputs.dump(2);
  EXPECT_EQ(outputs["spectra"]["times"], times) << outputs.dump(2);
  EXPECT_EQ(outputs["statistics"]["times"], times);
  EXPECT_EQ(outputs["slices"]["by_field"]["omega2"]["times"], times);
  EXPECT_EQ(outputs["slices"]["by_field"]["tau_sfs"]["count"], 3);
  EXPECT_EQ(outputs["snapshots"]["count"], 0);
  EXPECT_EQ(outputs["checkpoints"]["count"], 1);
  EXPECT_NE(r.output.find("written: "), std::string::npos) << r.output;
  EXPECT_NE(r.output.find(" 3 spectra,"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("slices omega2 3 tau_sfs 3"), std::string::npos) << r.output;
  for (const char* time : {"0.0000", "0.0500", "0.1000"})
    EXPECT_TRUE(
        std::filesystem::exists(out / "slices" / ("omega2_t" + std::string(time) + ".vti")));
}

TEST_F(CliTest, PresetsAreListedAndRunnableByName) {
  ProcessResult r = run_sphles("presets");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("tgv3d-case11"), std::string::npos);
  EXPECT_NE(r.output.find("kolmogorov2d"), std::string::npos);
  r = run_sphles(
      "run tgv3d-case17 --set particles_per_side=10 --set time.end=0.05 "
      "--set packing.enabled=false --out " +
      (dir_ / "c17").string());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const json written = json::parse(std::ifstream(dir_ / "c17" / "scene.json"));
  EXPECT_EQ(written["preset"], "tgv3d-case17");
  EXPECT_EQ(written["subfilter"]["model"], "smag_mcg");
  EXPECT_EQ(written["particles_per_side"], 10);
  r = run_sphles("run tgv3d-case99");
  EXPECT_EQ(r.exit_code, 2);
  // A preset's analysis section is the base of the run's: kolmogorov2d analyses every 0.25 s,
  // and a --set of its cadence keeps its products.
  const auto kolmogorov = dir_ / "kolmogorov";
  r = run_sphles(
      "run kolmogorov2d --set particles_per_side=16 --set time.end=0.2 "
      "--set packing.enabled=false --set analysis.every=0.1 --out " +
      kolmogorov.string());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const json analysed = json::parse(std::ifstream(kolmogorov / "scene.json"));
  EXPECT_EQ(analysed["analysis"]["every"], 0.1);
  EXPECT_EQ(analysed["analysis"]["products"],
            json::array({"energy", "spectrum", "vorticity", "slices", "sfs_stats"}));
  for (const char* file : {"spectra/E_t0.2000.csv", "slices/omega2_t0.2000.npy",
                           "slices/tau_sfs_t0.1000.npy", "stats/snapshots.csv"})
    EXPECT_TRUE(std::filesystem::exists(kolmogorov / file)) << file;
}

TEST_F(CliTest, CalibrateFindsForcingForTargetUrms) {
  // Laminar regime (u ∝ χ): the proportional second try lands within the tolerance.
  const auto scene = write("kol.json", R"({"case": "kolmogorov2d", "particles_per_side": 16,
      "fluid": {"reference_pressure": 1.0}, "packing": {"enabled": false},
      "forcing": {"amplitude": 0.01, "periods": 1, "friction": 4.0}})");
  ProcessResult r = run_sphles(
      "calibrate " + scene + " --target-urms 0.004 --time 1.5 --average-from 1.0 --tolerance 0.01");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("try 1: chi = 0.01"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("try 2:"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("converged: chi = "), std::string::npos) << r.output;
  r = run_sphles("calibrate tgv3d-case1 --target-urms 0.1");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.output.find("needs a kolmogorov2d scene"), std::string::npos) << r.output;
  r = run_sphles("calibrate " + scene);
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.output.find("--target-urms is required"), std::string::npos) << r.output;
}

TEST_F(CliTest, MovieEncodesTheSavedFramesAndNamesWhatIsMissing) {
  const auto scene = write("rendered.json", R"({"case": "tgv2d", "particles_per_side": 16,
      "kernel": {"diameter_over_spacing": 4}, "time": {"end": 0.1},
      "packing": {"enabled": false},
      "analysis": {"every": 0.025, "products": ["slices"], "slice": {"fields": ["omega2"]}},
      "render": {"fields": ["omega2"], "width": 128, "height": 64}})");
  const auto out = dir_ / "out";
  ProcessResult r = run_sphles("run " + scene + " --out " + out.string());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  r = run_sphles("movie " + out.string() + " --fps 4");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("5 frames of omega2, 64x64 px, 1.2 s at 4 frames/s"), std::string::npos)
      << r.output;
  const auto video = out / "movies" / "omega2.webm";
  ASSERT_TRUE(std::filesystem::exists(video));
  std::ifstream in(video, std::ios::binary);
  char magic[4] = {};
  in.read(magic, 4);
  EXPECT_EQ(std::string(magic, 4), std::string("\x1A\x45\xDF\xA3"));  // EBML (WebM)
  r = run_sphles("movie " + out.string() + " --field tau_sfs");
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find("no saved frame of field 'tau_sfs'"), std::string::npos) << r.output;
  r = run_sphles("movie " + (dir_ / "nothing").string());
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("is not a run directory"), std::string::npos) << r.output;
  r = run_sphles("movie " + out.string() + " --fps 0");
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("--fps"), std::string::npos) << r.output;
}

/// Every column of every CSV file under `run` (but units.csv) has its row in run/units.csv,
/// the file matched with '*' standing for a time.
void expect_units_for_every_column(const std::filesystem::path& run) {
  std::ifstream units_file(run / "units.csv");
  ASSERT_TRUE(units_file) << run;
  std::vector<std::array<std::string, 3>> units;
  std::string line;
  std::getline(units_file, line);
  EXPECT_EQ(line, "file,column,unit");
  while (std::getline(units_file, line)) {
    const auto a = line.find(','), b = line.find(',', a + 1);
    units.push_back({line.substr(0, a), line.substr(a + 1, b - a - 1), line.substr(b + 1)});
    EXPECT_FALSE(units.back()[2].empty()) << line;
  }
  const auto matches = [](const std::string& pattern, const std::string& file) {
    const auto star = pattern.find('*');
    if (star == std::string::npos) return pattern == file;
    const std::string head = pattern.substr(0, star), tail = pattern.substr(star + 1);
    return file.size() >= head.size() + tail.size() && file.starts_with(head) &&
           file.ends_with(tail);
  };
  int columns = 0;
  for (const auto& entry : std::filesystem::recursive_directory_iterator(run)) {
    const std::string file = std::filesystem::relative(entry.path(), run).string();
    if (entry.path().extension() != ".csv" || file == "units.csv") continue;
    std::ifstream csv(entry.path());
    std::string header;
    std::getline(csv, header);
    std::stringstream cells(header);
    for (std::string column; std::getline(cells, column, ',');) {
      ++columns;
      EXPECT_TRUE(std::any_of(units.begin(), units.end(),
                              [&](const auto& u) { return u[1] == column && matches(u[0], file); }))
          << file << ": column '" << column << "' has no unit in units.csv";
    }
  }
  EXPECT_GT(columns, 40) << run;
}

TEST_F(CliTest, UnitsCsvGivesTheUnitOfEveryColumnOfTheRunsCsvFiles) {
  const auto scene = write("everything.json", R"({"case": "tgv2d", "particles_per_side": 16,
      "kernel": {"diameter_over_spacing": 4}, "time": {"end": 0.1},
      "packing": {"enabled": false},
      "analysis": {"every": 0.05, "products": ["energy", "spectrum", "vorticity", "slices",
          "sfs_stats", "particles", "fields"], "slice": {"fields": ["omega2", "tau_sfs"]},
          "grid_fields": ["omega2"]},
      "render": {"fields": ["omega2"], "width": 128, "height": 64}})");
  ProcessResult r = run_sphles("run " + scene + " --out " + (dir_ / "all").string());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  expect_units_for_every_column(dir_ / "all");
  r = run_sphles(
      "run kolmogorov2d --set particles_per_side=16 --set time.end=0.1 "
      "--set packing.enabled=false --set analysis.every=0.05 --out " +
      (dir_ / "forced").string());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  expect_units_for_every_column(dir_ / "forced");
  r = run_sphles("reference tgv2d --set reference.points_per_side=16 --set time.end=0.1 --out " +
                 (dir_ / "reference").string());
  ASSERT_EQ(r.exit_code, 0) << r.output;
  expect_units_for_every_column(dir_ / "reference");
}

TEST_F(CliTest, CompareJudgesARunAgainstAReferenceAndItsKernelFilteredForm) {
  // A 24² 2D Taylor-Green run with D_K = 4Δl (k_kern = 6, k_SPH = 3) against a 32² reference of
  // the same flow: the vortices' energy lies in shell 1.
  const auto scene = write("tgv.json", R"({"case": "tgv2d", "particles_per_side": 24,
      "kernel": {"diameter_over_spacing": 4}, "time": {"end": 0.1}, "packing": {"enabled": false},
      "analysis": {"every": 0.05, "products": ["energy", "spectrum"]}})");
  const std::string run = (dir_ / "run").string(), ref = (dir_ / "ref").string();
  ProcessResult r = run_sphles("run " + scene + " --out " + run);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  r = run_sphles("reference " + scene + " --set reference.points_per_side=32 --out " + ref);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  r = run_sphles("compare " + run + " " + ref);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("k_kern = 6, k_SPH = 3"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("(each shell over the 3 times)"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("E_res misfit: L2"), std::string::npos) << r.output;
  const auto plain =
      nlohmann::json::parse(run_sphles("compare " + run + " " + ref + " --json").output);
  const auto filtered = nlohmann::json::parse(
      run_sphles("compare " + run + " " + ref + " --json --filter kernel").output);
  EXPECT_EQ(plain.at("filter"), "none");
  EXPECT_EQ(filtered.at("filter"), "kernel");
  // Filtering divides each ratio by Ŵ(k)² of the run's kernel at its D_K (2π/24 · 4).
  const double w =
      kernel_transfer(KernelType::WendlandC4, 2, 0.5 * 4.0 * 2.0 * std::numbers::pi / 24.0, 1.0);
  const auto& samples = plain.at("samples");
  ASSERT_EQ(samples.size(), 3u);
  double run_sum = 0.0, ref_sum = 0.0;
  for (std::size_t i = 0; i < samples.size(); ++i) {
    const double ratio = samples[i].at("shell_ratio")[0];
    EXPECT_NEAR(filtered.at("samples")[i].at("shell_ratio")[0].get<double>(), ratio / (w * w),
                1e-12 * ratio);
    run_sum += ratio * samples[i].at("reference_resolved_energy").get<double>();
    ref_sum += samples[i].at("reference_resolved_energy").get<double>();
  }
  // The window's ratio weighs each time by the shell's energy (here all resolved energy).
  EXPECT_NEAR(plain.at("mean_shell_ratio").at("ratio")[0].get<double>(), run_sum / ref_sum, 1e-9);
  EXPECT_LT(plain.at("mean_shell_ratio").at("ratio")[0].get<double>(), 1.0);
  r = run_sphles("compare " + run + " " + ref + " --filter kernel");
  EXPECT_NE(r.output.find("filtered by the run's kernel"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("W(k)^2 of wendland_c4"), std::string::npos) << r.output;
  r = run_sphles("compare " + run + " " + ref + " --filter gaussian");
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("--filter"), std::string::npos) << r.output;
}

}  // namespace
}  // namespace sphles::sim
