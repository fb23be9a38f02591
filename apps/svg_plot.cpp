#include "svg_plot.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <ostream>
#include <sstream>

#include "planeslam/datasets/atomic_file.hpp"

namespace planeslam::app {
namespace {

/// Coordinates with two decimals: sub-pixel precision without bloating the file.
std::string Num(double v) {
  char buffer[32];
  std::snprintf(buffer, sizeof(buffer), "%.2f", v);
  return buffer;
}

/// Tick spacing of 1, 2 or 5 times a power of ten giving about `target` intervals.
double NiceStep(double range, int target) {
  const double raw = range / target;
  const double magnitude = std::pow(10.0, std::floor(std::log10(raw)));
  const double norm = raw / magnitude;
  const double nice = norm < 1.5 ? 1.0 : norm < 3.0 ? 2.0 : norm < 7.0 ? 5.0 : 10.0;
  return nice * magnitude;
}

std::string TickLabel(double value, double step) {
  const int decimals = std::max(0, static_cast<int>(-std::floor(std::log10(step) + 1e-9)));
  char buffer[48];
  if (std::abs(value) < step * 1e-6) value = 0.0;  // no "-0.0"
  if (decimals > 6 || std::abs(value) >= 1e7) {
    std::snprintf(buffer, sizeof(buffer), "%.3g", value);
  } else {
    std::snprintf(buffer, sizeof(buffer), "%.*f", decimals, value);
  }
  return buffer;
}

struct Range {
  double lo = std::numeric_limits<double>::infinity();
  double hi = -std::numeric_limits<double>::infinity();
  void Add(double v) {
    if (!std::isfinite(v)) return;
    lo = std::min(lo, v);
    hi = std::max(hi, v);
  }
  bool Valid() const { return lo <= hi; }
  /// Pads by `fraction` of the span; an empty or zero span becomes a unit one.
  void Pad(double fraction) {
    if (!Valid()) {
      lo = 0.0;
      hi = 1.0;
      return;
    }
    double span = hi - lo;
    if (span <= 0.0) {
      const double half = lo != 0.0 ? 0.5 * std::abs(lo) : 0.5;
      lo -= half;
      hi += half;
      return;
    }
    lo -= fraction * span;
    hi += fraction * span;
  }
};

}  // namespace

std::string SvgColor::Hex() const {
  char buffer[8];
  std::snprintf(buffer, sizeof(buffer), "#%02x%02x%02x", r, g, b);
  return buffer;
}

SvgColor ColorMap(double t) {
  // Viridis sampled at nine points (matplotlib's table), linearly interpolated.
  static const std::uint8_t kTable[9][3] = {{68, 1, 84},    {72, 40, 120},  {62, 73, 137},
                                            {49, 104, 142}, {38, 130, 142}, {31, 158, 137},
                                            {53, 183, 121}, {110, 206, 88}, {253, 231, 37}};
  if (!std::isfinite(t)) t = 0.0;
  t = std::clamp(t, 0.0, 1.0) * 8.0;
  const int i = std::min(7, static_cast<int>(t));
  const double f = t - i;
  SvgColor c;
  auto mix = [&](int k) {
    return static_cast<std::uint8_t>(
        std::lround(kTable[i][k] + f * (kTable[i + 1][k] - kTable[i][k])));
  };
  c.r = mix(0);
  c.g = mix(1);
  c.b = mix(2);
  return c;
}

SvgColor CycleColor(int i) {
  static const std::uint8_t kTab10[10][3] = {
      {31, 119, 180}, {255, 127, 14},  {44, 160, 44},   {214, 39, 40},  {148, 103, 189},
      {140, 86, 75},  {227, 119, 194}, {127, 127, 127}, {188, 189, 34}, {23, 190, 207}};
  const int k = ((i % 10) + 10) % 10;
  return SvgColor{kTab10[k][0], kTab10[k][1], kTab10[k][2]};
}

BoxStats ComputeBoxStats(const std::string& label, std::vector<double> values) {
  BoxStats box;
  box.label = label;
  values.erase(
      std::remove_if(values.begin(), values.end(), [](double v) { return !std::isfinite(v); }),
      values.end());
  if (values.empty()) return box;
  std::sort(values.begin(), values.end());
  auto percentile = [&](double p) {  // numpy.percentile, method "linear"
    const double pos = p * static_cast<double>(values.size() - 1);
    const std::size_t i = static_cast<std::size_t>(std::floor(pos));
    const std::size_t j = std::min(i + 1, values.size() - 1);
    return values[i] + (pos - static_cast<double>(i)) * (values[j] - values[i]);
  };
  box.min = values.front();
  box.q1 = percentile(0.25);
  box.median = percentile(0.5);
  box.q3 = percentile(0.75);
  box.max = values.back();
  return box;
}

std::string XmlEscape(const std::string& text) {
  std::string out;
  for (char c : text) {
    switch (c) {
      case '&':
        out += "&amp;";
        break;
      case '<':
        out += "&lt;";
        break;
      case '>':
        out += "&gt;";
        break;
      case '"':
        out += "&quot;";
        break;
      case '\'':
        out += "&apos;";
        break;
      default:
        out += c;
    }
  }
  return out;
}

SvgPlot::SvgPlot(std::string title, std::string x_label, std::string y_label)
    : title_(std::move(title)), x_label_(std::move(x_label)), y_label_(std::move(y_label)) {}

void SvgPlot::SetSize(int width, int height) {
  width_ = std::max(200, width);
  height_ = std::max(150, height);
}

void SvgPlot::AddLine(const std::vector<double>& x, const std::vector<double>& y,
                      const LineStyle& style, const std::string& legend) {
  Series s{Series::Kind::kLine, x, y, {}, style, 0.0, legend};
  series_.push_back(std::move(s));
}

void SvgPlot::AddScatter(const std::vector<double>& x, const std::vector<double>& y, SvgColor color,
                         const std::string& legend, double radius) {
  LineStyle style;
  style.color = color;
  series_.push_back({Series::Kind::kScatter, x, y, {}, style, radius, legend});
}

void SvgPlot::AddColorMappedScatter(const std::vector<double>& x, const std::vector<double>& y,
                                    const std::vector<double>& values,
                                    const std::string& colorbar_label, double vmin, double vmax,
                                    double radius) {
  if (!(vmin < vmax)) {
    Range r;
    for (double v : values) r.Add(v);
    vmin = r.Valid() ? r.lo : 0.0;
    vmax = r.Valid() && r.hi > r.lo ? r.hi : vmin + 1.0;
  }
  cmin_ = vmin;
  cmax_ = vmax;
  colorbar_label_ = colorbar_label;
  has_colorbar_ = true;
  series_.push_back({Series::Kind::kColorScatter, x, y, values, LineStyle{}, radius, ""});
}

void SvgPlot::AddHorizontalLine(double y, const LineStyle& style, const std::string& legend) {
  series_.push_back({Series::Kind::kHLine, {}, {y}, {}, style, 0.0, legend});
}

void SvgPlot::AddBoxes(const std::vector<BoxStats>& boxes, SvgColor color) {
  boxes_ = boxes;
  box_color_ = color;
}

/// The plot area [px] and the data ranges it shows; maps data coordinates to pixels.
struct SvgPlot::Layout {
  double left = 80, top = 40, bottom = 60, right = 25;  ///< margins [px]
  double pw = 0, ph = 0;                                ///< plot area [px]
  double x_lo = 0, x_hi = 1, y_lo = 0, y_hi = 1;        ///< data ranges shown
  double sx = 1, sy = 1;                                ///< scale [px per data unit]
  double X(double x) const { return left + (x - x_lo) * sx; }
  double Y(double y) const { return top + ph - (y - y_lo) * sy; }
};

SvgPlot::Layout SvgPlot::ComputeLayout() const {
  // Margins for tick labels and axis labels; a strip on the right for the colour bar.
  Layout l;
  l.right = has_colorbar_ ? 110 : 25;
  l.pw = width_ - l.left - l.right;
  l.ph = height_ - l.top - l.bottom;

  Range xr, yr;
  for (const Series& s : series_) {
    if (s.kind == Series::Kind::kHLine) {
      yr.Add(s.y[0]);
      continue;
    }
    for (std::size_t i = 0; i < s.x.size() && i < s.y.size(); ++i) {
      if (std::isfinite(s.x[i]) && std::isfinite(s.y[i])) {
        xr.Add(s.x[i]);
        yr.Add(s.y[i]);
      }
    }
  }
  for (std::size_t i = 0; i < boxes_.size(); ++i) {
    xr.Add(static_cast<double>(i) + 0.5);
    xr.Add(static_cast<double>(i) + 1.5);
    yr.Add(boxes_[i].min);
    yr.Add(boxes_[i].max);
  }
  for (std::size_t i = 0; i < categories_.size(); ++i) {
    xr.Add(static_cast<double>(i) + 0.5);
    xr.Add(static_cast<double>(i) + 1.5);
  }
  if (boxes_.empty() && categories_.empty()) xr.Pad(0.03);
  yr.Pad(0.05);
  double sx = l.pw / (xr.hi - xr.lo), sy = l.ph / (yr.hi - yr.lo);
  if (equal_aspect_) {  // widen the tighter axis around its centre
    const double s = std::min(sx, sy);
    const double cx = 0.5 * (xr.lo + xr.hi), cy = 0.5 * (yr.lo + yr.hi);
    xr.lo = cx - 0.5 * l.pw / s;
    xr.hi = cx + 0.5 * l.pw / s;
    yr.lo = cy - 0.5 * l.ph / s;
    yr.hi = cy + 0.5 * l.ph / s;
    sx = sy = s;
  }
  l.x_lo = xr.lo;
  l.x_hi = xr.hi;
  l.y_lo = yr.lo;
  l.y_hi = yr.hi;
  l.sx = sx;
  l.sy = sy;
  return l;
}

void SvgPlot::RenderHeader(std::ostream& o, const Layout& l) const {
  o << "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n"
    << "<svg xmlns=\"http://www.w3.org/2000/svg\" version=\"1.1\" width=\"" << width_
    << "\" height=\"" << height_ << "\" viewBox=\"0 0 " << width_ << ' ' << height_
    << "\" font-family=\"Helvetica, Arial, sans-serif\" font-size=\"12\">\n";
  o << "<title>" << XmlEscape(title_) << "</title>\n";
  o << "<defs>\n<clipPath id=\"plot-area\"><rect x=\"" << Num(l.left) << "\" y=\"" << Num(l.top)
    << "\" width=\"" << Num(l.pw) << "\" height=\"" << Num(l.ph) << "\"/></clipPath>\n";
  if (has_colorbar_) {
    o << "<linearGradient id=\"colorbar\" x1=\"0\" y1=\"1\" x2=\"0\" y2=\"0\">\n";
    for (int k = 0; k <= 8; ++k) {
      o << "<stop offset=\"" << Num(k / 8.0) << "\" stop-color=\"" << ColorMap(k / 8.0).Hex()
        << "\"/>\n";
    }
    o << "</linearGradient>\n";
  }
  o << "</defs>\n";
  o << "<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n";
}

void SvgPlot::RenderGrid(std::ostream& o, const Layout& l) const {
  o << "<g stroke=\"#e0e0e0\" stroke-width=\"1\">\n";
  const double xstep = NiceStep(l.x_hi - l.x_lo, 8), ystep = NiceStep(l.y_hi - l.y_lo, 6);
  std::ostringstream labels;
  if (boxes_.empty() && categories_.empty()) {
    for (double x = std::ceil(l.x_lo / xstep) * xstep; x <= l.x_hi + 1e-9 * xstep; x += xstep) {
      o << "<line x1=\"" << Num(l.X(x)) << "\" y1=\"" << Num(l.top) << "\" x2=\"" << Num(l.X(x))
        << "\" y2=\"" << Num(l.top + l.ph) << "\"/>\n";
      labels << "<text x=\"" << Num(l.X(x)) << "\" y=\"" << Num(l.top + l.ph + 16)
             << "\" text-anchor=\"middle\">" << TickLabel(x, xstep) << "</text>\n";
    }
  } else {
    const std::size_t n = boxes_.empty() ? categories_.size() : boxes_.size();
    for (std::size_t i = 0; i < n; ++i) {
      const std::string& label = boxes_.empty() ? categories_[i] : boxes_[i].label;
      labels << "<text x=\"" << Num(l.X(static_cast<double>(i) + 1.0)) << "\" y=\""
             << Num(l.top + l.ph + 16) << "\" text-anchor=\"middle\">" << XmlEscape(label)
             << "</text>\n";
    }
  }
  for (double y = std::ceil(l.y_lo / ystep) * ystep; y <= l.y_hi + 1e-9 * ystep; y += ystep) {
    o << "<line x1=\"" << Num(l.left) << "\" y1=\"" << Num(l.Y(y)) << "\" x2=\""
      << Num(l.left + l.pw) << "\" y2=\"" << Num(l.Y(y)) << "\"/>\n";
    labels << "<text x=\"" << Num(l.left - 6) << "\" y=\"" << Num(l.Y(y) + 4)
           << "\" text-anchor=\"end\">" << TickLabel(y, ystep) << "</text>\n";
  }
  o << "</g>\n<g fill=\"#333333\">\n" << labels.str() << "</g>\n";
}

void SvgPlot::RenderBoxes(std::ostream& o, const Layout& l) const {
  for (std::size_t i = 0; i < boxes_.size(); ++i) {
    const BoxStats& b = boxes_[i];
    const double c = l.X(static_cast<double>(i) + 1.0), hw = 0.25 * l.sx;
    const std::string color = box_color_.Hex();
    o << "<g stroke=\"" << color << "\" stroke-width=\"1.5\" fill=\"none\">\n";
    o << "<line x1=\"" << Num(c) << "\" y1=\"" << Num(l.Y(b.min)) << "\" x2=\"" << Num(c)
      << "\" y2=\"" << Num(l.Y(b.q1)) << "\"/>\n";
    o << "<line x1=\"" << Num(c) << "\" y1=\"" << Num(l.Y(b.q3)) << "\" x2=\"" << Num(c)
      << "\" y2=\"" << Num(l.Y(b.max)) << "\"/>\n";
    o << "<line x1=\"" << Num(c - 0.5 * hw) << "\" y1=\"" << Num(l.Y(b.min)) << "\" x2=\""
      << Num(c + 0.5 * hw) << "\" y2=\"" << Num(l.Y(b.min)) << "\"/>\n";
    o << "<line x1=\"" << Num(c - 0.5 * hw) << "\" y1=\"" << Num(l.Y(b.max)) << "\" x2=\""
      << Num(c + 0.5 * hw) << "\" y2=\"" << Num(l.Y(b.max)) << "\"/>\n";
    o << "<rect x=\"" << Num(c - hw) << "\" y=\"" << Num(l.Y(b.q3)) << "\" width=\"" << Num(2 * hw)
      << "\" height=\"" << Num(std::max(0.0, l.Y(b.q1) - l.Y(b.q3))) << "\" fill=\"" << color
      << "\" fill-opacity=\"0.25\"/>\n";
    o << "<line x1=\"" << Num(c - hw) << "\" y1=\"" << Num(l.Y(b.median)) << "\" x2=\""
      << Num(c + hw) << "\" y2=\"" << Num(l.Y(b.median)) << "\" stroke-width=\"2.5\"/>\n";
    o << "</g>\n";
  }
}

void SvgPlot::RenderLine(std::ostream& o, const Layout& l, const Series& s) {
  const std::string dash = s.style.dashed ? " stroke-dasharray=\"6,4\"" : "";
  // NaN points break the line: each finite run is one polyline.
  std::ostringstream points;
  auto flush = [&]() {
    if (points.tellp() > 0) {
      o << "<polyline fill=\"none\" stroke=\"" << s.style.color.Hex() << "\" stroke-width=\""
        << Num(s.style.width) << "\" stroke-linejoin=\"round\"" << dash << " points=\""
        << points.str() << "\"/>\n";
    }
    points.str("");
    points.clear();
  };
  for (std::size_t i = 0; i < s.x.size() && i < s.y.size(); ++i) {
    if (!std::isfinite(s.x[i]) || !std::isfinite(s.y[i])) {
      flush();
      continue;
    }
    points << (points.tellp() > 0 ? " " : "") << Num(l.X(s.x[i])) << ',' << Num(l.Y(s.y[i]));
  }
  flush();
}

void SvgPlot::RenderPoints(std::ostream& o, const Layout& l, const Series& s) const {
  for (std::size_t i = 0; i < s.x.size() && i < s.y.size(); ++i) {
    if (!std::isfinite(s.x[i]) || !std::isfinite(s.y[i])) continue;
    const SvgColor c = s.kind == Series::Kind::kScatter
                           ? s.style.color
                           : ColorMap((s.values[i] - cmin_) / (cmax_ - cmin_));
    o << "<circle cx=\"" << Num(l.X(s.x[i])) << "\" cy=\"" << Num(l.Y(s.y[i])) << "\" r=\""
      << Num(s.radius) << "\" fill=\"" << c.Hex() << "\"/>\n";
  }
}

void SvgPlot::RenderHorizontalLine(std::ostream& o, const Layout& l, const Series& s) {
  const std::string dash = s.style.dashed ? " stroke-dasharray=\"6,4\"" : "";
  o << "<line x1=\"" << Num(l.left) << "\" y1=\"" << Num(l.Y(s.y[0])) << "\" x2=\""
    << Num(l.left + l.pw) << "\" y2=\"" << Num(l.Y(s.y[0])) << "\" stroke=\"" << s.style.color.Hex()
    << "\" stroke-width=\"" << Num(s.style.width) << "\"" << dash << "/>\n";
}

void SvgPlot::RenderData(std::ostream& o, const Layout& l) const {
  o << "<g clip-path=\"url(#plot-area)\">\n";
  RenderBoxes(o, l);
  for (const Series& s : series_) {
    switch (s.kind) {
      case Series::Kind::kLine:
        RenderLine(o, l, s);
        break;
      case Series::Kind::kScatter:
      case Series::Kind::kColorScatter:
        RenderPoints(o, l, s);
        break;
      case Series::Kind::kHLine:
        RenderHorizontalLine(o, l, s);
        break;
    }
  }
  o << "</g>\n";
}

void SvgPlot::RenderFrameAndLabels(std::ostream& o, const Layout& l) const {
  o << "<rect x=\"" << Num(l.left) << "\" y=\"" << Num(l.top) << "\" width=\"" << Num(l.pw)
    << "\" height=\"" << Num(l.ph) << "\" fill=\"none\" stroke=\"#333333\"/>\n";
  o << "<text x=\"" << Num(l.left + l.pw / 2)
    << "\" y=\"24\" text-anchor=\"middle\" font-size=\"15\">" << XmlEscape(title_) << "</text>\n";
  o << "<text x=\"" << Num(l.left + l.pw / 2) << "\" y=\"" << Num(height_ - 18)
    << "\" text-anchor=\"middle\" font-size=\"13\">" << XmlEscape(x_label_) << "</text>\n";
  o << "<text transform=\"translate(18," << Num(l.top + l.ph / 2)
    << ") rotate(-90)\" text-anchor=\"middle\" font-size=\"13\">" << XmlEscape(y_label_)
    << "</text>\n";
}

void SvgPlot::RenderLegend(std::ostream& o, const Layout& l) const {
  // Top right, inside the plot; one entry per series with a legend text.
  std::vector<const Series*> entries;
  for (const Series& s : series_) {
    if (!s.legend.empty()) entries.push_back(&s);
  }
  if (entries.empty()) return;
  std::size_t longest = 0;
  for (const Series* s : entries) longest = std::max(longest, s->legend.size());
  const double w = 40 + 6.5 * static_cast<double>(longest), h = 8 + 18.0 * entries.size();
  const double x0 = l.left + l.pw - w - 8, y0 = l.top + 8;
  o << "<g>\n<rect x=\"" << Num(x0) << "\" y=\"" << Num(y0) << "\" width=\"" << Num(w)
    << "\" height=\"" << Num(h) << "\" fill=\"white\" fill-opacity=\"0.85\" stroke=\"#999999\"/>\n";
  for (std::size_t k = 0; k < entries.size(); ++k) {
    const Series& s = *entries[k];
    const double y = y0 + 15 + 18.0 * k;
    if (s.kind == Series::Kind::kScatter) {
      o << "<circle cx=\"" << Num(x0 + 17) << "\" cy=\"" << Num(y - 4) << "\" r=\"3.5\" fill=\""
        << s.style.color.Hex() << "\"/>\n";
    } else {
      o << "<line x1=\"" << Num(x0 + 6) << "\" y1=\"" << Num(y - 4) << "\" x2=\"" << Num(x0 + 28)
        << "\" y2=\"" << Num(y - 4) << "\" stroke=\"" << s.style.color.Hex() << "\" stroke-width=\""
        << Num(s.style.width) << "\"" << (s.style.dashed ? " stroke-dasharray=\"6,4\"" : "")
        << "/>\n";
    }
    o << "<text x=\"" << Num(x0 + 34) << "\" y=\"" << Num(y) << "\">" << XmlEscape(s.legend)
      << "</text>\n";
  }
  o << "</g>\n";
}

void SvgPlot::RenderColorBar(std::ostream& o, const Layout& l) const {
  const double bx = l.left + l.pw + 20, bw = 16;
  o << "<rect x=\"" << Num(bx) << "\" y=\"" << Num(l.top) << "\" width=\"" << Num(bw)
    << "\" height=\"" << Num(l.ph) << "\" fill=\"url(#colorbar)\" stroke=\"#333333\"/>\n";
  const double cstep = NiceStep(cmax_ - cmin_, 5);
  for (double v = std::ceil(cmin_ / cstep) * cstep; v <= cmax_ + 1e-9 * cstep; v += cstep) {
    const double y = l.top + l.ph - (v - cmin_) / (cmax_ - cmin_) * l.ph;
    o << "<line x1=\"" << Num(bx + bw) << "\" y1=\"" << Num(y) << "\" x2=\"" << Num(bx + bw + 4)
      << "\" y2=\"" << Num(y) << "\" stroke=\"#333333\"/>\n";
    o << "<text x=\"" << Num(bx + bw + 6) << "\" y=\"" << Num(y + 4) << "\">" << TickLabel(v, cstep)
      << "</text>\n";
  }
  o << "<text transform=\"translate(" << Num(width_ - 12) << "," << Num(l.top + l.ph / 2)
    << ") rotate(-90)\" text-anchor=\"middle\" font-size=\"13\">" << XmlEscape(colorbar_label_)
    << "</text>\n";
}

std::string SvgPlot::Render() const {
  const Layout layout = ComputeLayout();
  std::ostringstream o;
  RenderHeader(o, layout);
  RenderGrid(o, layout);
  RenderData(o, layout);
  RenderFrameAndLabels(o, layout);
  RenderLegend(o, layout);
  if (has_colorbar_) RenderColorBar(o, layout);
  o << "</svg>\n";
  return o.str();
}

void SvgPlot::Write(const std::string& path) const { datasets::WriteFileAtomic(path, Render()); }

}  // namespace planeslam::app
