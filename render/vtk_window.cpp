// SPDX-License-Identifier: GPL-3.0-or-later
// Off-screen VTK window on OSMesa, read-back and PNG encoding, text actors and the colour bar.
#include "render/vtk_window.hpp"

#include <filesystem>

#include <vtkCoordinate.h>
#include <vtkImageData.h>
#include <vtkTextProperty.h>
#include <vtkUnsignedCharArray.h>

#include <algorithm>
#include <cstdio>
#include <stdexcept>

#include "render/lookup_table.hpp"

namespace sphles::render::detail {

std::mutex& vtk_scene_mutex() {
  static std::mutex mutex;
  return mutex;
}

double elapsed_ms(Clock::time_point since) {
  return std::chrono::duration<double, std::milli>(Clock::now() - since).count();
}

std::string format_number(double value) {
  char buffer[32];
  std::snprintf(buffer, sizeof buffer, "%.4g", value);
  return buffer;
}

namespace {

/// The font of the pictures' text: DejaVu Sans (Debian's fonts-dejavu-core, found at configure
/// time), whose glyphs include the Greek letters and superscripts of the labels; VTK's embedded
/// Arial, which has neither, when the file is missing.
const char* unicode_font() {
  static const char* const font = [] {
    const char* path = SPHLES_TEXT_FONT;
    return path[0] != '\0' && std::filesystem::is_regular_file(path) ? path : nullptr;
  }();
  return font;
}

}  // namespace

void set_font(vtkTextProperty* property) {
  if (const char* font = unicode_font()) {
    property->SetFontFamily(VTK_FONT_FILE);
    property->SetFontFile(font);
  } else {
    set_font(property);
  }
}

std::string field_symbol(analysis::SliceField field) {
  if (unicode_font() == nullptr) return std::string(analysis::slice_field_name(field));
  switch (field) {
    case analysis::SliceField::VorticitySquared:
      return "\u03c9\u00b2";  // ω²
    case analysis::SliceField::SubfilterStressNorm:
      return "|\u03c4_SFS|";  // |τ_SFS|
    case analysis::SliceField::EddyViscosity:
      return "\u03bd_t";  // ν_t
  }
  return std::string(analysis::slice_field_name(field));
}

std::string field_units(analysis::SliceField field) {
  if (unicode_font() == nullptr) return std::string(analysis::slice_field_units(field));
  switch (field) {
    case analysis::SliceField::VorticitySquared:
      return "s\u207b\u00b2";  // s⁻²
    case analysis::SliceField::SubfilterStressNorm:
      return "Pa";
    case analysis::SliceField::EddyViscosity:
      return "m\u00b2/s";  // m²/s
  }
  return std::string(analysis::slice_field_units(field));
}

std::string field_label(analysis::SliceField field) {
  return field_symbol(field) + " [" + field_units(field) + "]";
}

vtkSmartPointer<vtkTextActor> make_text(int justification, int vertical_justification,
                                        int font_size) {
  auto text = vtkSmartPointer<vtkTextActor>::New();
  text->SetTextScaleModeToNone();
  text->GetPositionCoordinate()->SetCoordinateSystemToViewport();
  vtkTextProperty* property = text->GetTextProperty();
  set_font(property);
  property->SetFontSize(font_size);
  property->SetColor(0.0, 0.0, 0.0);
  property->SetJustification(justification);
  property->SetVerticalJustification(vertical_justification);
  return text;
}

void set_text(vtkTextActor* actor, const std::string& text, double x, double y) {
  if (actor->GetInput() == nullptr || text != actor->GetInput()) actor->SetInput(text.c_str());
  actor->SetPosition(x, y);
}

ColourBar::ColourBar() {
  actor_->SetOrientationToVertical();
  actor_->SetMaximumNumberOfColors(kColourCount);
  actor_->SetNumberOfLabels(5);
  actor_->SetUnconstrainedFontSize(true);
  actor_->SetBarRatio(0.3);
  actor_->SetTextPad(3);
  actor_->SetLabelFormat("%.3g");
  actor_->GetPositionCoordinate()->SetCoordinateSystemToViewport();
  actor_->GetPosition2Coordinate()->SetCoordinateSystemToViewport();
  for (vtkTextProperty* property :
       {actor_->GetTitleTextProperty(), actor_->GetLabelTextProperty()}) {
    set_font(property);
    property->SetColor(0.0, 0.0, 0.0);
    property->SetBold(false);
    property->SetItalic(false);
    property->SetShadow(false);
    property->SetFontSize(kFontSize);
  }
  actor_->GetLabelTextProperty()->SetFontSize(kFontSize - 2);
}

void ColourBar::update(const std::array<double, 2>& range, bool log_scale, const std::string& title,
                       double x, double y, double width, double height) {
  if (range != range_ || log_scale != log_scale_ || actor_->GetLookupTable() == nullptr) {
    actor_->SetLookupTable(make_lookup_table(range, log_scale));
    range_ = range;
    log_scale_ = log_scale;
  }
  if (actor_->GetTitle() == nullptr || title != actor_->GetTitle()) {
    actor_->SetTitle(title.c_str());
  }
  actor_->SetPosition(x, y);
  actor_->SetPosition2(width, height);
}

OffscreenWindow::OffscreenWindow(int width, int height)
    : width_(width), height_(height), context_(width, height) {
  window_->SetOwnContext(false);
  window_->SetSize(width, height);
  window_->SetOffScreenRendering(true);
  window_->SetMultiSamples(0);
  window_->SetIsDirect(true);
  window_->SetSupportsOpenGL(true);
  window_->SetReadyForRendering(true);
  window_->SetIsCurrent(true);
  window_->SetMapped(true);

  read_back_->SetInput(window_);
  read_back_->ShouldRerenderOff();
  read_back_->ReadFrontBufferOff();
  read_back_->SetInputBufferTypeToRGB();

  writer_->SetInputConnection(read_back_->GetOutputPort());
  writer_->WriteToMemoryOn();
  writer_->SetCompressionLevel(compression_level_);
}

OffscreenWindow::~OffscreenWindow() {
  // VTK releases its GL objects on destruction: keep the context current until it has.
  try {
    context_.make_current();
  } catch (...) {
    return;  // cannot release GL resources safely; leak them rather than crash
  }
  writer_ = nullptr;
  read_back_ = nullptr;
  window_->Finalize();
  window_ = nullptr;
}

void OffscreenWindow::set_compression_level(int level) {
  compression_level_ = std::clamp(level, 0, 9);
  writer_->SetCompressionLevel(compression_level_);
}

std::vector<unsigned char> OffscreenWindow::read_back_png(FrameTimings& timings) {
  auto start = Clock::now();
  read_back_->Modified();
  read_back_->Update();
  timings.read_back_ms = elapsed_ms(start);

  start = Clock::now();
  std::vector<unsigned char> bytes;
  if (png_filter_) {
    vtkImageData* image = read_back_->GetOutput();
    int* dimensions = image->GetDimensions();
    const auto* pixels = static_cast<const unsigned char*>(image->GetScalarPointer());
    bytes = encode_png_rgb(
        std::span(pixels, static_cast<std::size_t>(dimensions[0]) * dimensions[1] * 3),
        dimensions[0], dimensions[1], compression_level_, *png_filter_);
  } else {
    writer_->Write();
    vtkUnsignedCharArray* result = writer_->GetResult();
    if (result == nullptr || result->GetNumberOfValues() == 0) {
      throw std::runtime_error("render_png: PNG encoding failed");
    }
    bytes.assign(result->GetPointer(0), result->GetPointer(0) + result->GetNumberOfValues());
  }
  timings.encode_ms = elapsed_ms(start);
  return bytes;
}

}  // namespace sphles::render::detail
