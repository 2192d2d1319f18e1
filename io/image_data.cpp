// SPDX-License-Identifier: GPL-3.0-or-later
#include "io/image_data.hpp"

#include <vtkDoubleArray.h>
#include <vtkFieldData.h>
#include <vtkImageData.h>
#include <vtkNew.h>
#include <vtkPointData.h>
#include <vtkStringArray.h>
#include <vtkXMLImageDataWriter.h>
#include <vtkZLibDataCompressor.h>

#include <unistd.h>
#include <cstdio>
#include <sstream>
#include <stdexcept>

#include "io/hdf5_file.hpp"

namespace sphles::io {

namespace {

constexpr const char* kImageSchema = "sphles-image 1";

std::string text_array_entry(const ImageArray& a) {
  return a.name + " [" + a.units + "]";
}

}  // namespace

void write_vti(const std::filesystem::path& path, const ImageData& image,
               const std::string& code_version) {
  const std::string label = "image '" + path.string() + "'";
  const std::size_t points = static_cast<std::size_t>(image.dimensions[0]) *
                             static_cast<std::size_t>(image.dimensions[1]) *
                             static_cast<std::size_t>(image.dimensions[2]);
  vtkNew<vtkImageData> data;
  data->SetDimensions(image.dimensions.data());
  data->SetOrigin(image.origin.data());
  data->SetSpacing(image.spacing.data());
  vtkNew<vtkStringArray> units;
  units->SetName("units");
  for (const ImageArray& a : image.arrays) {
    if (a.components < 1 || a.values.size() != points * static_cast<std::size_t>(a.components))
      throw std::runtime_error(label + ": array '" + a.name + "' has " +
                               std::to_string(a.values.size()) + " values for " +
                               std::to_string(points) + " points x " +
                               std::to_string(a.components) + " components");
    vtkNew<vtkDoubleArray> array;
    array->SetName(a.name.c_str());
    array->SetNumberOfComponents(a.components);
    array->SetNumberOfTuples(static_cast<vtkIdType>(points));
    std::copy(a.values.begin(), a.values.end(), array->GetPointer(0));
    data->GetPointData()->AddArray(array);
    units->InsertNextValue(text_array_entry(a));
  }
  vtkNew<vtkDoubleArray> time;
  time->SetName("TimeValue");
  time->InsertNextValue(image.time);
  vtkNew<vtkStringArray> schema, version;
  schema->SetName("schema");
  schema->InsertNextValue(kImageSchema);
  version->SetName("code_version");
  version->InsertNextValue(code_version);
  data->GetFieldData()->AddArray(time);
  data->GetFieldData()->AddArray(units);
  data->GetFieldData()->AddArray(schema);
  data->GetFieldData()->AddArray(version);

  const std::filesystem::path temporary =
      path.string() + ".tmp." + std::to_string(static_cast<long>(::getpid()));
  vtkNew<vtkXMLImageDataWriter> writer;
  vtkNew<vtkZLibDataCompressor> compressor;
  writer->SetCompressor(compressor);
  writer->SetDataModeToAppended();
  writer->EncodeAppendedDataOff();
  writer->SetFileName(temporary.c_str());
  writer->SetInputData(data);
  const int ok = writer->Write();
  if (ok != 1 || writer->GetErrorCode() != 0) {
    std::error_code ignored;
    std::filesystem::remove(temporary, ignored);
    throw std::runtime_error(label + ": VTK could not write it (error code " +
                             std::to_string(writer->GetErrorCode()) + ")");
  }
  std::error_code ec;
  std::filesystem::rename(temporary, path, ec);
  if (ec) {
    std::filesystem::remove(temporary, ec);
    throw std::runtime_error(label + ": cannot rename the temporary file: " + ec.message());
  }
}

void write_pvd(const std::filesystem::path& path, const std::vector<CollectionEntry>& entries) {
  std::ostringstream x;
  x.precision(17);
  x << "<?xml version=\"1.0\"?>\n"
    << "<VTKFile type=\"Collection\" version=\"0.1\" byte_order=\"LittleEndian\">\n"
    << "  <Collection>\n";
  for (const CollectionEntry& e : entries)
    x << "    <DataSet timestep=\"" << e.time << "\" group=\"\" part=\"0\" file=\"" << e.file
      << "\"/>\n";
  x << "  </Collection>\n</VTKFile>\n";
  detail::write_file_atomically(path, x.str(), "collection '" + path.string() + "'");
}

}  // namespace sphles::io
