#pragma once
/// A small dependency-free SVG plot writer: axes with "nice" ticks, labels, title, polylines
/// (solid or dashed), scatter points with a fixed colour or colour-mapped by a value (with a colour
/// bar), horizontal reference lines, box plots and a legend. Used by `planeslam eval` and the
/// benchmark plots; the output is standalone SVG 1.1 that browsers and `xmllint` accept.
#include <cstdint>
#include <iosfwd>
#include <string>
#include <vector>

namespace planeslam::app {

/// An sRGB colour.
struct SvgColor {
  std::uint8_t r = 0, g = 0, b = 0;
  /// "#rrggbb".
  std::string Hex() const;
};

/// The perceptually ordered "viridis" colour map at t in [0, 1] (clamped).
SvgColor ColorMap(double t);

/// Matplotlib's default colour cycle ("tab10"), entry i modulo 10.
SvgColor CycleColor(int i);

struct LineStyle {
  SvgColor color = CycleColor(0);
  double width = 1.5;  ///< [px]
  bool dashed = false;
};

/// Five-number summary drawn by AddBoxes.
struct BoxStats {
  std::string label;
  double min = 0, q1 = 0, median = 0, q3 = 0, max = 0;
};

/// Box statistics of `values` (quartiles by linear interpolation, as numpy.percentile).
BoxStats ComputeBoxStats(const std::string& label, std::vector<double> values);

class SvgPlot {
 public:
  SvgPlot(std::string title, std::string x_label, std::string y_label);

  /// Total image size [px]; default 800 x 500.
  void SetSize(int width, int height);
  /// Same scale on both axes (top views of trajectories).
  void SetEqualAspect(bool equal) { equal_aspect_ = equal; }

  /// A polyline through (x[i], y[i]); NaN points break the line. Empty legend: no legend entry.
  void AddLine(const std::vector<double>& x, const std::vector<double>& y, const LineStyle& style,
               const std::string& legend = "");
  /// Points of one colour.
  void AddScatter(const std::vector<double>& x, const std::vector<double>& y, SvgColor color,
                  const std::string& legend = "", double radius = 2.5);
  /// Points coloured by `values` through ColorMap over [vmin, vmax] (vmin == vmax: the data range);
  /// draws a colour bar labelled `colorbar_label`. One colour-mapped series per plot.
  void AddColorMappedScatter(const std::vector<double>& x, const std::vector<double>& y,
                             const std::vector<double>& values, const std::string& colorbar_label,
                             double vmin = 0.0, double vmax = 0.0, double radius = 2.5);
  /// A horizontal line across the plot at y (e.g. the mean or the RMSE).
  void AddHorizontalLine(double y, const LineStyle& style, const std::string& legend = "");
  /// Named categories at x = 1, 2, ... as x tick labels (series over categories, e.g. sequences).
  void SetXCategories(std::vector<std::string> labels) { categories_ = std::move(labels); }
  /// Box plots at x = 1, 2, ... with the boxes' labels as x tick labels.
  void AddBoxes(const std::vector<BoxStats>& boxes, SvgColor color = CycleColor(0));

  /// The SVG document.
  std::string Render() const;
  /// Renders and writes atomically; throws IoError naming `path` on failure.
  void Write(const std::string& path) const;

 private:
  struct Series {
    enum class Kind { kLine, kScatter, kColorScatter, kHLine } kind;
    std::vector<double> x, y, values;
    LineStyle style;
    double radius = 2.5;
    std::string legend;
  };
  /// The plot area and the data-to-pixel mapping (svg_plot.cpp).
  struct Layout;

  Layout ComputeLayout() const;
  /// XML prolog, title, clip path, colour-bar gradient, white background.
  void RenderHeader(std::ostream& o, const Layout& l) const;
  /// Grid lines and tick labels (box labels on the x axis of box plots).
  void RenderGrid(std::ostream& o, const Layout& l) const;
  /// Boxes and series, clipped to the plot area.
  void RenderData(std::ostream& o, const Layout& l) const;
  void RenderBoxes(std::ostream& o, const Layout& l) const;
  static void RenderLine(std::ostream& o, const Layout& l, const Series& s);
  void RenderPoints(std::ostream& o, const Layout& l, const Series& s) const;
  static void RenderHorizontalLine(std::ostream& o, const Layout& l, const Series& s);
  /// Frame of the plot area, title and axis labels.
  void RenderFrameAndLabels(std::ostream& o, const Layout& l) const;
  void RenderLegend(std::ostream& o, const Layout& l) const;
  void RenderColorBar(std::ostream& o, const Layout& l) const;

  std::string title_, x_label_, y_label_;
  int width_ = 800, height_ = 500;
  bool equal_aspect_ = false;
  std::vector<Series> series_;
  std::vector<BoxStats> boxes_;
  std::vector<std::string> categories_;
  SvgColor box_color_;
  std::string colorbar_label_;
  double cmin_ = 0.0, cmax_ = 0.0;
  bool has_colorbar_ = false;
};

/// Escapes &, <, >, " and ' for XML text and attributes.
std::string XmlEscape(const std::string& text);

}  // namespace planeslam::app
