// SPDX-License-Identifier: GPL-3.0-or-later
// Image data outputs read back with VTK's own XML readers (the VTK the build links): values,
// shape, origin, spacing, units and time survive bit for bit; a slice written by the run
// directory writer reads back as the slice the analysis computed; bad input is a clear error.
#include <gtest/gtest.h>
#include <vtkDoubleArray.h>
#include <vtkFieldData.h>
#include <vtkImageData.h>
#include <vtkNew.h>
#include <vtkPointData.h>
#include <vtkSmartPointer.h>
#include <vtkStringArray.h>
#include <vtkXMLDataElement.h>
#include <vtkXMLImageDataReader.h>
#include <vtkXMLUtilities.h>

#include <cmath>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>

#include "analysis/config.hpp"
#include "analysis/products.hpp"
#include "analysis/writer.hpp"
#include "io/image_data.hpp"
#include "scene/document.hpp"
#include "sim/initial_conditions.hpp"
#include "sim/scene.hpp"
#include "sim/solver.hpp"
#include "test_support.hpp"

namespace {

using namespace sphles;

class OutputReaders : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = std::filesystem::temp_directory_path() /
           ("sphles_readers_" + std::to_string(::getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    std::filesystem::remove_all(dir_);
    std::filesystem::create_directories(dir_);
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }
  std::filesystem::path dir_;
};

vtkSmartPointer<vtkImageData> read_vti(const std::filesystem::path& path) {
  vtkNew<vtkXMLImageDataReader> reader;
  EXPECT_TRUE(reader->CanReadFile(path.c_str())) << path;
  reader->SetFileName(path.c_str());
  reader->Update();
  EXPECT_EQ(reader->GetErrorCode(), 0u);
  vtkSmartPointer<vtkImageData> image = reader->GetOutput();
  return image;
}

std::string field_text(vtkImageData* image, const char* name, int index = 0) {
  auto* array = vtkStringArray::SafeDownCast(image->GetFieldData()->GetAbstractArray(name));
  return array && array->GetNumberOfValues() > index ? array->GetValue(index) : "";
}

TEST_F(OutputReaders, ImageDataRoundTripsThroughVtkXmlImageDataReader) {
  io::ImageData image;
  image.dimensions = {5, 4, 3};
  image.origin = {0.5, -1.0, 2.25};
  image.spacing = {0.1, 0.2, 0.3};
  image.time = 1.375;
  const std::size_t n = 5 * 4 * 3;
  io::ImageArray scalar{"omega2", "1/s^2", 1, {}}, vector{"velocity", "m/s", 3, {}};
  for (std::size_t k = 0; k < n; ++k) scalar.values.push_back(std::sin(0.37 * k) / 3.0);
  for (std::size_t k = 0; k < 3 * n; ++k) vector.values.push_back(std::exp(-0.01 * k) - 0.5);
  image.arrays = {scalar, vector};
  const auto path = dir_ / "field.vti";
  io::write_vti(path, image, "9.9.9");
  EXPECT_FALSE(std::filesystem::exists(path.string() + ".tmp." + std::to_string(::getpid())));

  const auto read = read_vti(path);
  int dims[3];
  read->GetDimensions(dims);
  EXPECT_EQ(dims[0], 5);
  EXPECT_EQ(dims[1], 4);
  EXPECT_EQ(dims[2], 3);
  for (int d = 0; d < 3; ++d) {
    EXPECT_EQ(read->GetOrigin()[d], image.origin[static_cast<std::size_t>(d)]);
    EXPECT_EQ(read->GetSpacing()[d], image.spacing[static_cast<std::size_t>(d)]);
  }
  for (const io::ImageArray& expected : image.arrays) {
    auto* array =
        vtkDoubleArray::SafeDownCast(read->GetPointData()->GetArray(expected.name.c_str()));
    ASSERT_NE(array, nullptr) << expected.name;
    ASSERT_EQ(array->GetNumberOfComponents(), expected.components);
    ASSERT_EQ(static_cast<std::size_t>(array->GetNumberOfValues()), expected.values.size());
    for (std::size_t k = 0; k < expected.values.size(); ++k)
      ASSERT_EQ(array->GetValue(static_cast<vtkIdType>(k)), expected.values[k]) << k;
  }
  auto* time = vtkDoubleArray::SafeDownCast(read->GetFieldData()->GetArray("TimeValue"));
  ASSERT_NE(time, nullptr);
  EXPECT_EQ(time->GetValue(0), 1.375);
  EXPECT_EQ(field_text(read, "units", 0), "omega2 [1/s^2]");
  EXPECT_EQ(field_text(read, "units", 1), "velocity [m/s]");
  EXPECT_EQ(field_text(read, "code_version"), "9.9.9");
  EXPECT_EQ(field_text(read, "schema"), "sphles-image 1");
}

TEST_F(OutputReaders, BadImagesAreClearErrorsAndLeaveNoFile) {
  io::ImageData image;
  image.dimensions = {3, 3, 1};
  image.arrays = {{"tau_sfs", "Pa", 1, std::vector<double>(8, 1.0)}};
  try {
    io::write_vti(dir_ / "bad.vti", image, "x");
    FAIL() << "expected an error";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("array 'tau_sfs' has 8 values for 9 points"),
              std::string::npos)
        << e.what();
  }
  image.arrays[0].values.resize(9);
  std::ofstream(dir_ / "plain") << "not a directory";
  const auto nowhere = dir_ / "plain" / "slice.vti";
  try {
    io::write_vti(nowhere, image, "x");
    FAIL() << "expected an error";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find(nowhere.string()), std::string::npos) << e.what();
  }
  std::size_t files = 0;
  for ([[maybe_unused]] const auto& entry : std::filesystem::directory_iterator(dir_)) ++files;
  EXPECT_EQ(files, 1u);  // only "plain"
}

/// A 3D run's x-normal slices and a 2D run's slice, written by the run directory writer, read
/// back by VTK as the plane and values the analysis computed; the .pvd lists them by time.
TEST_F(OutputReaders, SlicesReadBackAsTheAnalysedPlane) {
  for (const char* case_name : {"tgv3d", "tgv2d"}) {
    const auto run = dir_ / case_name;
    const sim::Scene scene = scene::parse_scene(
        {{"case", case_name}, {"particles_per_side", 12}, {"packing", {{"enabled", false}}}});
    sim::RunSetup setup = sim::setup_run(scene, {});
    auto simulation = sim::make_simulation(setup.solver, std::move(setup.particles));
    analysis::AnalysisConfig config;
    config.every = 0.1;
    config.products = {analysis::Product::Slices};
    config.slice.fields = {analysis::SliceField::VorticitySquared,
                           analysis::SliceField::SubfilterStressNorm};
    analysis::RunDirectoryWriter writer(run, {"{}", "test"});
    std::vector<analysis::AnalysisFrame> frames;
    for (int k = 0; k < 2; ++k) {
      if (k > 0) simulation->step();
      frames.push_back(analysis::analyse(*analysis::make_snapshot(*simulation), config));
      writer.write(frames.back());
    }
    ASSERT_EQ(writer.last_error(), "");
    for (const analysis::AnalysisFrame& frame : frames)
      for (const analysis::SliceProduct& slice : frame.slices) {
        const std::string field(analysis::slice_field_name(slice.field));
        const auto read =
            read_vti(run / "slices" / analysis::timed_file_name(field, frame.time, ".vti"));
        int dims[3];
        read->GetDimensions(dims);
        EXPECT_EQ(dims[slice.axis_u], slice.width);
        EXPECT_EQ(dims[slice.axis_v], slice.height);
        EXPECT_EQ(dims[slice.normal_axis], 1);
        EXPECT_EQ(read->GetOrigin()[slice.normal_axis], slice.position);
        EXPECT_EQ(read->GetSpacing()[slice.axis_u], slice.spacing);
        auto* array = vtkDoubleArray::SafeDownCast(read->GetPointData()->GetArray(field.c_str()));
        ASSERT_NE(array, nullptr);
        ASSERT_EQ(static_cast<std::size_t>(array->GetNumberOfValues()), slice.values.size());
        for (std::size_t k = 0; k < slice.values.size(); ++k)
          ASSERT_EQ(array->GetValue(static_cast<vtkIdType>(k)), slice.values[k]);
        // The point at (iu, iv) is at (iu h, iv h) in the plane (SliceProduct).
        double point[3];
        const vtkIdType last = read->GetNumberOfPoints() - 1;
        read->GetPoint(last, point);
        EXPECT_NEAR(point[slice.axis_u], (slice.width - 1) * slice.spacing, 1e-12);
        EXPECT_NEAR(point[slice.axis_v], (slice.height - 1) * slice.spacing, 1e-12);
        EXPECT_EQ(field_text(read, "units"), field + " [" + slice.units + "]");
      }
    for (const char* field : {"omega2", "tau_sfs"}) {
      vtkSmartPointer<vtkXMLDataElement> root;
      root.TakeReference(vtkXMLUtilities::ReadElementFromFile(
          (run / "slices" / (std::string(field) + ".pvd")).c_str()));
      ASSERT_NE(root, nullptr) << field;
      EXPECT_STREQ(root->GetAttribute("type"), "Collection");
      vtkXMLDataElement* collection = root->FindNestedElementWithName("Collection");
      ASSERT_NE(collection, nullptr);
      ASSERT_EQ(collection->GetNumberOfNestedElements(), 2);
      for (int k = 0; k < 2; ++k) {
        vtkXMLDataElement* entry = collection->GetNestedElement(k);
        EXPECT_EQ(std::stod(entry->GetAttribute("timestep")), frames[k].time);
        EXPECT_EQ(std::string(entry->GetAttribute("file")),
                  analysis::timed_file_name(field, frames[k].time, ".vti"));
      }
    }
  }
}

/// The "fields" product: the whole analysis grid as one .vti per snapshot. VTK reads back the
/// grid's shape and spacing, a 3-component velocity and the scalars, whose x-normal plane is the
/// slice the same frame carries, bit for bit; the .pvd lists the files by time.
TEST_F(OutputReaders, GridFieldsReadBackAsTheAnalysisGrid) {
  const auto run = dir_ / "fields";
  const sim::Scene scene = scene::parse_scene(
      {{"case", "tgv3d"}, {"particles_per_side", 12}, {"packing", {{"enabled", false}}}});
  sim::RunSetup setup = sim::setup_run(scene, {});
  auto simulation = sim::make_simulation(setup.solver, std::move(setup.particles));
  analysis::AnalysisConfig config;
  config.every = 0.1;
  config.products = {analysis::Product::Slices, analysis::Product::Fields};
  config.slice.fields = {analysis::SliceField::VorticitySquared,
                         analysis::SliceField::SubfilterStressNorm};
  config.grid_fields = config.slice.fields;
  analysis::RunDirectoryWriter writer(run, {"{}", "test"});
  const analysis::AnalysisFrame frame =
      analysis::analyse(*analysis::make_snapshot(*simulation), config);
  writer.write(frame);
  ASSERT_EQ(writer.last_error(), "");
  ASSERT_TRUE(frame.fields);
  const int m = frame.fields->grid.points_per_side;
  EXPECT_EQ(m, 24);
  const auto read = read_vti(run / "fields" / analysis::timed_file_name("fields", 0.0, ".vti"));
  int dims[3];
  read->GetDimensions(dims);
  EXPECT_EQ(dims[0], m);
  EXPECT_EQ(dims[1], m);
  EXPECT_EQ(dims[2], m);
  EXPECT_EQ(read->GetSpacing()[0], frame.fields->grid.spacing());
  auto* velocity = vtkDoubleArray::SafeDownCast(read->GetPointData()->GetArray("velocity"));
  ASSERT_NE(velocity, nullptr);
  ASSERT_EQ(velocity->GetNumberOfComponents(), 3);
  // The nearest-particle velocity keeps its mean (zero for the TGV); on the lattice every
  // particle is the nearest of some node, so the peak is the particles' peak.
  double particle_peak = 0.0;
  for (const double u : simulation->particles().velocity[0])
    particle_peak = std::max(particle_peak, std::abs(u));
  double peak = 0.0, mean = 0.0;
  for (vtkIdType n = 0; n < velocity->GetNumberOfTuples(); ++n) {
    peak = std::max(peak, std::abs(velocity->GetComponent(n, 0)));
    mean += velocity->GetComponent(n, 0) / static_cast<double>(velocity->GetNumberOfTuples());
    EXPECT_EQ(velocity->GetComponent(n, 0), frame.fields->velocity->component[0][n]);
  }
  EXPECT_EQ(peak, particle_peak);
  EXPECT_NEAR(mean, 0.0, 1e-12);
  for (const analysis::SliceProduct& slice : frame.slices) {
    const std::string field(analysis::slice_field_name(slice.field));
    auto* array = vtkDoubleArray::SafeDownCast(read->GetPointData()->GetArray(field.c_str()));
    ASSERT_NE(array, nullptr) << field;
    const int i = static_cast<int>(std::lround(slice.position / slice.spacing));
    for (int k = 0; k < m; ++k)
      for (int j = 0; j < m; ++j)
        ASSERT_EQ(array->GetValue(i + m * (j + m * k)),
                  slice.values[static_cast<std::size_t>(j + m * k)])
            << field << " at " << j << ", " << k;
    EXPECT_NE(field_text(read, "units", field == "omega2" ? 1 : 2).find(slice.units),
              std::string::npos);
  }
  vtkSmartPointer<vtkXMLDataElement> root;
  root.TakeReference(vtkXMLUtilities::ReadElementFromFile((run / "fields" / "fields.pvd").c_str()));
  ASSERT_NE(root, nullptr);
  EXPECT_EQ(root->FindNestedElementWithName("Collection")->GetNumberOfNestedElements(), 1);
}

TEST(GridFieldsConfig, BadListsAreClearErrors) {
  const auto error = [](const nlohmann::json& analysis) {
    nlohmann::json scene = {{"case", "tgv3d"}, {"particles_per_side", 12}, {"analysis", analysis}};
    try {
      analysis::parse_run_config(scene);
    } catch (const sim::SceneError& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  const nlohmann::json base = {{"every", 0.5}, {"products", {"fields"}}};
  nlohmann::json a = base;
  a["grid_fields"] = {"velocity", "pressure"};
  EXPECT_NE(error(a).find("'analysis.grid_fields[1]' must be one of"), std::string::npos)
      << error(a);
  a["grid_fields"] = {"omega2", "velocity", "omega2"};
  EXPECT_NE(error(a).find("'analysis.grid_fields[2]' repeats 'omega2'"), std::string::npos)
      << error(a);
  a["grid_fields"] = {"nu_t"};
  EXPECT_NE(error(a).find("asks for nu_t, but 'subfilter.model' is implicit"), std::string::npos)
      << error(a);
  a["grid_fields"] = nlohmann::json::array();
  EXPECT_NE(error(a).find("'analysis.grid_fields' is empty"), std::string::npos) << error(a);
  a["grid_fields"] = {"velocity", "tau_sfs"};
  EXPECT_EQ(error(a), "");
  const analysis::RunConfig parsed =
      analysis::parse_run_config({{"case", "tgv3d"}, {"particles_per_side", 12}, {"analysis", a}});
  EXPECT_TRUE(parsed.analysis.grid_velocity);
  EXPECT_EQ(analysis::run_config_to_json(parsed)["analysis"]["grid_fields"],
            nlohmann::json({"velocity", "tau_sfs"}));
}

}  // namespace
