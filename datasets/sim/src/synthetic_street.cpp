// The street scene (roads, kerbs, sidewalks, buildings, furniture, parked cars) and the route
// around its central block.
#include "planeslam/datasets/synthetic_street.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <string>

#include "planeslam/datasets/errors.hpp"
#include "planeslam/datasets/synthetic_sequence.hpp"
#include "scene_builder.hpp"
#include "synthetic_random.hpp"

namespace planeslam::datasets {

namespace {

using detail::SceneBuilder;
using Eigen::Vector3d;
constexpr double kPi = 3.14159265358979323846;
constexpr double kDeg = kPi / 180.0;
const Vector3d kUp = Vector3d::UnitZ();

/// A rectangular opening in a facade, in facade coordinates: u along the facade, w up from the
/// facade's foot [m].
struct Opening {
  double u0, u1, w0, w1;
};

/// One side of a block that faces a street. The facade normal n points to the street; u runs
/// along e_u = z x n. Kerb line: kerb0 + u e_u for u in [0, kerb_length]; the building line is
/// `sidewalk` further inside and runs over [build0, build1]; the sidewalk strip over
/// [strip0, strip1].
struct BlockSide {
  Vector3d kerb0;
  Vector3d n;
  Vector3d e_u;
  double kerb_length = 0.0;
  double build0 = 0.0, build1 = 0.0;
  double strip0 = 0.0, strip1 = 0.0;
  std::string name;
};

class StreetBuilder {
 public:
  explicit StreetBuilder(std::uint64_t seed)
      : b_("street"), rng_(seed ^ 0x5354524545545ULL), L_(DefaultStreetLayout()) {
    road_edge_z_ = -L_.camber * L_.road_half_width;
    top_z_ = road_edge_z_ + L_.kerb;
    end_x_ = L_.street_x + L_.side_street;
    end_y_ = L_.street_y + L_.side_street;
  }

  SyntheticScene Build() {
    Roads();
    const double hw = L_.road_half_width, X = L_.street_x, Y = L_.street_y;
    // The central block, the four blocks beside it and the four corner blocks.
    const std::array<double, 4> xs = {-end_x_, -X, X, end_x_};
    const std::array<double, 4> ys = {-end_y_, -Y, Y, end_y_};
    for (int i = 0; i < 3; ++i) {
      for (int j = 0; j < 3; ++j) {
        const double x0 = xs[i] + (i > 0 ? hw : 0.0), x1 = xs[i + 1] - (i < 2 ? hw : 0.0);
        const double y0 = ys[j] + (j > 0 ? hw : 0.0), y1 = ys[j + 1] - (j < 2 ? hw : 0.0);
        Block("block" + std::to_string(3 * j + i), x0, x1, y0, y1, /*south=*/j > 0,
              /*east=*/i < 2, /*north=*/j < 2, /*west=*/i > 0);
      }
    }
    StreetEnds();
    SyntheticScene scene = b_.Take();
    PLANESLAM_CHECK(scene.planes.size() < 65535, "street scene: too many planes for 16-bit labels");
    return scene;
  }

 private:
  /// Road surfaces: each half of each street is one plane (camber), cut into pieces of at most
  /// 5 m; inside the crossings z = -camber * min(|dx|, |dy|), i.e. two triangles of each half.
  void Roads() {
    const double hw = L_.road_half_width, c = L_.camber;
    for (double Y : {-L_.street_y, L_.street_y}) {
      for (int side : {1, -1}) {  // north half (y > Y), south half
        const std::string name = "road.y" + std::to_string(static_cast<int>(Y)) +
                                 (side > 0 ? ".north" : ".south");
        int id = 0;
        auto piece = [&](std::vector<Vector3d> corners) {
          if (id == 0) {
            id = b_.AddPolygon(name, std::move(corners));
          } else {
            b_.AddPiece(id, std::move(corners));
          }
        };
        auto along = [&](double x0, double x1) {
          const int n = std::max(1, static_cast<int>(std::ceil((x1 - x0) / 5.0)));
          for (int k = 0; k < n; ++k) {
            const double a = x0 + (x1 - x0) * k / n, e = x0 + (x1 - x0) * (k + 1) / n;
            const double yo = Y + side * hw;
            // Corners counter-clockwise seen from above (the road faces up).
            if (side > 0) {
              piece({{a, Y, 0}, {e, Y, 0}, {e, yo, -c * hw}, {a, yo, -c * hw}});
            } else {
              piece({{a, yo, -c * hw}, {e, yo, -c * hw}, {e, Y, 0}, {a, Y, 0}});
            }
          }
        };
        along(-end_x_, -L_.street_x - hw);
        along(-L_.street_x + hw, L_.street_x - hw);
        along(L_.street_x + hw, end_x_);
        for (double X : {-L_.street_x, L_.street_x}) {
          const double yo = Y + side * hw;
          if (side > 0) {
            piece({{X, Y, 0}, {X + hw, Y, 0}, {X + hw, yo, -c * hw}});
            piece({{X, Y, 0}, {X - hw, yo, -c * hw}, {X - hw, Y, 0}});
          } else {
            piece({{X + hw, yo, -c * hw}, {X + hw, Y, 0}, {X, Y, 0}});
            piece({{X - hw, Y, 0}, {X - hw, yo, -c * hw}, {X, Y, 0}});
          }
        }
      }
    }
    for (double X : {-L_.street_x, L_.street_x}) {
      for (int side : {1, -1}) {  // east half (x > X), west half
        const std::string name = "road.x" + std::to_string(static_cast<int>(X)) +
                                 (side > 0 ? ".east" : ".west");
        int id = 0;
        auto piece = [&](std::vector<Vector3d> corners) {
          if (id == 0) {
            id = b_.AddPolygon(name, std::move(corners));
          } else {
            b_.AddPiece(id, std::move(corners));
          }
        };
        const double xo = X + side * hw;
        auto along = [&](double y0, double y1) {
          const int n = std::max(1, static_cast<int>(std::ceil((y1 - y0) / 5.0)));
          for (int k = 0; k < n; ++k) {
            const double a = y0 + (y1 - y0) * k / n, e = y0 + (y1 - y0) * (k + 1) / n;
            if (side > 0) {
              piece({{X, a, 0}, {xo, a, -c * hw}, {xo, e, -c * hw}, {X, e, 0}});
            } else {
              piece({{xo, a, -c * hw}, {X, a, 0}, {X, e, 0}, {xo, e, -c * hw}});
            }
          }
        };
        along(-end_y_, -L_.street_y - hw);
        along(-L_.street_y + hw, L_.street_y - hw);
        along(L_.street_y + hw, end_y_);
        for (double Y : {-L_.street_y, L_.street_y}) {
          if (side > 0) {
            piece({{X, Y, 0}, {xo, Y + hw, -c * hw}, {X, Y + hw, 0}});
            piece({{X, Y, 0}, {X, Y - hw, 0}, {xo, Y - hw, -c * hw}});
          } else {
            piece({{X, Y, 0}, {X, Y + hw, 0}, {xo, Y + hw, -c * hw}});
            piece({{X, Y, 0}, {xo, Y - hw, -c * hw}, {X, Y - hw, 0}});
          }
        }
      }
    }
  }

  /// The buildings closing the side streets.
  void StreetEnds() {
    const double w = L_.road_half_width + L_.sidewalk, h = 14.0;
    for (double Y : {-L_.street_y, L_.street_y}) {
      for (double sx : {-1.0, 1.0}) {
        const Vector3d n(-sx, 0, 0);
        const Vector3d c(sx * end_x_, Y, road_edge_z_ + 0.5 * h);
        b_.AddRect("end.y" + std::to_string(static_cast<int>(Y)) + (sx > 0 ? ".east" : ".west"),
                   c, w * kUp.cross(n), 0.5 * h * kUp);
      }
    }
    for (double X : {-L_.street_x, L_.street_x}) {
      for (double sy : {-1.0, 1.0}) {
        const Vector3d n(0, -sy, 0);
        const Vector3d c(X, sy * end_y_, road_edge_z_ + 0.5 * h);
        b_.AddRect("end.x" + std::to_string(static_cast<int>(X)) + (sy > 0 ? ".north" : ".south"),
                   c, w * kUp.cross(n), 0.5 * h * kUp);
      }
    }
  }

  /// A block with kerb rectangle [x0, x1] x [y0, y1]; the flags say which sides face a street.
  void Block(const std::string& name, double x0, double x1, double y0, double y1, bool south,
             bool east, bool north, bool west) {
    const double sw = L_.sidewalk;
    std::vector<BlockSide> sides;
    auto add = [&](const std::string& side_name, const Vector3d& k0, const Vector3d& n,
                   double length, bool start_faces, bool end_faces, bool full_strip) {
      BlockSide s;
      s.kerb0 = k0;
      s.n = n;
      s.e_u = kUp.cross(n);
      s.kerb_length = length;
      s.build0 = start_faces ? sw : 0.0;
      s.build1 = length - (end_faces ? sw : 0.0);
      s.strip0 = full_strip ? 0.0 : s.build0;
      s.strip1 = full_strip ? length : s.build1;
      s.name = name + "." + side_name;
      sides.push_back(s);
    };
    // Along e_u = z x n: south runs +x, east +y, north -x, west -y.
    if (south) add("s", {x0, y0, 0}, -Vector3d::UnitY(), x1 - x0, west, east, true);
    if (east) add("e", {x1, y0, 0}, Vector3d::UnitX(), y1 - y0, south, north, false);
    if (north) add("n", {x1, y1, 0}, Vector3d::UnitY(), x1 - x0, east, west, true);
    if (west) add("w", {x0, y1, 0}, -Vector3d::UnitX(), y1 - y0, north, south, false);
    if (sides.empty()) return;
    sidewalk_id_ = 0;
    sidewalk_name_ = name + ".sidewalk";
    for (const BlockSide& s : sides) {
      Kerb(s);
      Sidewalk(s.kerb0 + s.strip0 * s.e_u - sw * s.n, s.e_u, s.n, s.strip1 - s.strip0, sw);
      Buildings(s);
      Furniture(s);
      Cars(s);
    }
  }

  /// Adds a horizontal rectangle of the block's sidewalk plane: from `start` (on its inner edge)
  /// `length` along e_u and `depth` towards n.
  void Sidewalk(const Vector3d& start, const Vector3d& e_u, const Vector3d& n, double length,
                double depth) {
    if (length <= 1e-6 || depth <= 1e-6) return;
    const int pieces = std::max(1, static_cast<int>(std::ceil(length / 10.0)));
    for (int k = 0; k < pieces; ++k) {
      const double u = length * (k + 0.5) / pieces;
      Vector3d c = start + u * e_u + 0.5 * depth * n;
      c.z() = top_z_;
      // e_u x (-n) = z: the piece faces up.
      auto corners = SceneBuilder::Rect(c, 0.5 * length / pieces * e_u, 0.5 * depth * (-n));
      if (sidewalk_id_ == 0) {
        sidewalk_id_ = b_.AddPolygon(sidewalk_name_, std::move(corners));
      } else {
        b_.AddPiece(sidewalk_id_, std::move(corners));
      }
    }
  }

  void Kerb(const BlockSide& s) {
    const int pieces = std::max(1, static_cast<int>(std::ceil(s.kerb_length / 10.0)));
    int id = 0;
    for (int k = 0; k < pieces; ++k) {
      const double u = s.kerb_length * (k + 0.5) / pieces;
      Vector3d c = s.kerb0 + u * s.e_u;
      c.z() = 0.5 * (road_edge_z_ + top_z_);
      auto corners = SceneBuilder::Rect(c, 0.5 * s.kerb_length / pieces * s.e_u, 0.5 * L_.kerb * kUp);
      if (id == 0) {
        id = b_.AddPolygon(s.name + ".kerb", std::move(corners));
      } else {
        b_.AddPiece(id, std::move(corners));
      }
    }
  }

  /// Buildings along the building line: widths 12..28 m, heights 10..22 m, setbacks 0 (corner
  /// buildings, and half of the others) or 0.3..1.5 m; each with a recessed door and shop windows.
  void Buildings(const BlockSide& s) {
    std::vector<double> cuts = {s.build0};
    while (s.build1 - cuts.back() > 40.0) cuts.push_back(cuts.back() + rng_.Uniform(12.0, 28.0));
    if (s.build1 - cuts.back() > 24.0) cuts.push_back(0.5 * (cuts.back() + s.build1));
    cuts.push_back(s.build1);
    const std::size_t count = cuts.size() - 1;
    std::vector<double> setback(count, 0.0), height(count, 0.0);
    for (std::size_t k = 0; k < count; ++k) {
      height[k] = rng_.Uniform(10.0, 22.0);
      const bool corner = k == 0 || k + 1 == count;
      setback[k] = (!corner && rng_.Uniform() < 0.5) ? rng_.Uniform(0.3, 1.5) : 0.0;
    }
    const Vector3d line0 = s.kerb0 - L_.sidewalk * s.n;  // building line at u = 0
    for (std::size_t k = 0; k < count; ++k) {
      const std::string name = s.name + ".b" + std::to_string(k);
      const double u0 = cuts[k], u1 = cuts[k + 1], sb = setback[k];
      Facade(name, line0 - sb * s.n, s.e_u, s.n, u0, u1, height[k]);
      if (sb > 0.0) Sidewalk(line0 + u0 * s.e_u - sb * s.n, s.e_u, s.n, u1 - u0, sb);
      if (k + 1 < count && setback[k + 1] != sb) {
        // The side wall of the building that stands forward, facing the receding one.
        const double sa = sb, sn = setback[k + 1];
        const bool this_forward = sa < sn;
        const double h = this_forward ? height[k] : height[k + 1];
        Vector3d c = line0 + u1 * s.e_u - 0.5 * (sa + sn) * s.n;
        c.z() = top_z_ + 0.5 * h;
        const double half = 0.5 * std::abs(sn - sa);
        // (-n) x z = e_u: faces +u when this building stands forward.
        b_.AddRect(name + ".side", c, (this_forward ? -half : half) * s.n, 0.5 * h * kUp);
      }
    }
  }

  /// One facade from u0 to u1 on the plane through `line0` (at u = 0) with normal n, with a
  /// recessed door and shop windows on the ground floor.
  void Facade(const std::string& name, const Vector3d& line0, const Vector3d& e_u,
              const Vector3d& n, double u0, double u1, double height) {
    std::vector<Opening> doors, windows;
    const double width = u1 - u0;
    if (width > 6.0) {
      const double wd = rng_.Uniform(1.0, 1.8);
      const double ud = rng_.Uniform(1.5, width - 1.5 - wd);
      doors.push_back({ud, ud + wd, 0.0, 2.3});
    }
    double u = rng_.Uniform(0.8, 2.0);
    while (true) {
      const double ww = rng_.Uniform(1.2, 2.6);
      if (u + ww > width - 0.8) break;
      const bool clash = std::any_of(doors.begin(), doors.end(), [&](const Opening& d) {
        return u < d.u1 + 0.6 && u + ww > d.u0 - 0.6;
      });
      if (!clash) windows.push_back({u, u + ww, 0.7, 2.5});
      u += ww + rng_.Uniform(0.9, 2.0);
    }
    std::vector<Opening> holes = doors;
    holes.insert(holes.end(), windows.begin(), windows.end());
    // Facade pieces: bands between the openings' heights, solid intervals in each band.
    std::vector<double> ws = {0.0, height};
    for (const Opening& h : holes) {
      ws.push_back(h.w0);
      ws.push_back(h.w1);
    }
    std::sort(ws.begin(), ws.end());
    ws.erase(std::unique(ws.begin(), ws.end()), ws.end());
    const Vector3d foot = line0 + top_z_ * kUp;  // facade foot at u = 0
    int id = 0;
    for (std::size_t i = 0; i + 1 < ws.size(); ++i) {
      const double wa = ws[i], wb = ws[i + 1];
      std::vector<std::pair<double, double>> cut;
      for (const Opening& h : holes) {
        if (h.w0 <= wa && h.w1 >= wb) cut.emplace_back(h.u0, h.u1);
      }
      std::sort(cut.begin(), cut.end());
      double start = 0.0;
      cut.emplace_back(width, width);
      for (const auto& [c0, c1] : cut) {
        if (c0 > start + 1e-9) {
          const Vector3d c = foot + (u0 + 0.5 * (start + c0)) * e_u + 0.5 * (wa + wb) * kUp;
          auto corners = SceneBuilder::Rect(c, 0.5 * (c0 - start) * e_u, 0.5 * (wb - wa) * kUp);
          if (id == 0) {
            id = b_.AddPolygon(name, std::move(corners));
          } else {
            b_.AddPiece(id, std::move(corners));
          }
        }
        start = std::max(start, c1);
      }
    }
    for (std::size_t k = 0; k < doors.size(); ++k) {
      Recess(name + ".door" + std::to_string(k), foot + u0 * e_u, e_u, n, doors[k], 0.35, true);
    }
    for (std::size_t k = 0; k < windows.size(); ++k) {
      Recess(name + ".window" + std::to_string(k), foot + u0 * e_u, e_u, n, windows[k], 0.15,
             false);
    }
  }

  /// The faces of a recessed opening: the back (door leaf or pane), the two reveals, the head,
  /// and the sill (window) or a piece of the sidewalk (door).
  void Recess(const std::string& name, const Vector3d& foot, const Vector3d& e_u,
              const Vector3d& n, const Opening& o, double depth, bool door) {
    const double uc = 0.5 * (o.u0 + o.u1), wc = 0.5 * (o.w0 + o.w1);
    const double hu = 0.5 * (o.u1 - o.u0), hw = 0.5 * (o.w1 - o.w0), hd = 0.5 * depth;
    const Vector3d back = foot + uc * e_u + wc * kUp - depth * n;
    b_.AddRect(name, back, hu * e_u, hw * kUp);  // e_u x z = n
    const Vector3d mid = foot + uc * e_u + wc * kUp - hd * n;
    b_.AddRect(name + ".reveal0", mid - hu * e_u, hd * (-n), hw * kUp);  // faces +e_u
    b_.AddRect(name + ".reveal1", mid + hu * e_u, hd * n, hw * kUp);     // faces -e_u
    b_.AddRect(name + ".head", mid + hw * kUp, hu * e_u, hd * n);       // faces down
    if (door) {
      Sidewalk(foot + o.u0 * e_u - depth * n, e_u, n, o.u1 - o.u0, depth);
    } else {
      b_.AddRect(name + ".sill", mid - hw * kUp, hu * e_u, hd * (-n));  // faces up
    }
  }

  /// Lamp poles every 25 +- 3 m, sign posts with a plate, trees on half of the sides; all on the
  /// sidewalk near the kerb, clear of the crossings.
  void Furniture(const BlockSide& s) {
    const double margin = 8.0;
    const double base = top_z_;
    std::vector<double> lamps;
    for (double u = s.strip0 + margin + rng_.Uniform(0.0, 10.0); u < s.strip1 - margin;
         u += rng_.Uniform(22.0, 28.0)) {
      lamps.push_back(u);
      Vector3d p = s.kerb0 + u * s.e_u - 0.5 * s.n;
      p.z() = base;
      b_.AddCylinder(s.name + ".lamp" + std::to_string(lamps.size() - 1), p, kUp, 6.5, 0.1, false,
                     false);
    }
    auto near_lamp = [&](double u) {
      return std::any_of(lamps.begin(), lamps.end(), [u](double l) { return std::abs(l - u) < 2.0; });
    };
    int signs = 0;
    for (double u = s.strip0 + margin + rng_.Uniform(5.0, 30.0); u < s.strip1 - margin;
         u += rng_.Uniform(40.0, 70.0)) {
      if (near_lamp(u)) continue;
      Vector3d p = s.kerb0 + u * s.e_u - 0.4 * s.n;
      p.z() = base;
      const std::string name = s.name + ".sign" + std::to_string(signs++);
      b_.AddCylinder(name + ".post", p, kUp, 2.6, 0.035, false, false);
      // The plate faces along the street, just in front of the post.
      const Vector3d facing = rng_.Uniform() < 0.5 ? s.e_u : Vector3d(-s.e_u);
      const Vector3d c = p + 0.05 * facing + 2.2 * kUp;
      b_.AddRect(name, c, 0.3 * kUp.cross(facing), 0.3 * kUp);  // (z x f) x z = f
    }
    if (rng_.Uniform() < 0.5) return;
    int trees = 0;
    for (double u = s.strip0 + margin + rng_.Uniform(0.0, 6.0); u < s.strip1 - margin;
         u += rng_.Uniform(9.0, 13.0)) {
      if (near_lamp(u)) continue;
      Vector3d p = s.kerb0 + u * s.e_u - 1.4 * s.n;
      p.z() = base;
      const double trunk = rng_.Uniform(2.2, 3.0), crown = rng_.Uniform(1.3, 1.7);
      b_.AddCylinder(s.name + ".tree" + std::to_string(trees++), p, kUp, trunk,
                     rng_.Uniform(0.12, 0.2), false, false);
      b_.AddSphere(p + (trunk + 0.7 * crown) * kUp, crown);
    }
  }

  /// Cars parked along the kerb (centre 1 m onto the road), in 6.5 m slots filled with
  /// probability 0.5, at least 12 m from a crossing; each a body box and a cabin box.
  void Cars(const BlockSide& s) {
    int cars = 0;
    for (double u = 12.0; u + 6.5 < s.kerb_length - 12.0; u += 6.5) {
      if (rng_.Uniform() < 0.5) continue;
      const double length = rng_.Uniform(3.9, 4.8), width = rng_.Uniform(1.7, 1.85);
      const double yaw = std::atan2(s.e_u.y(), s.e_u.x()) + rng_.Uniform(-1.5, 1.5) * kDeg;
      Vector3d p = s.kerb0 + (u + 3.25) * s.e_u + 1.0 * s.n;
      const double ground = StreetGroundHeight(p.x(), p.y());
      const std::string name = s.name + ".car" + std::to_string(cars++);
      p.z() = ground + 0.3 + 0.375;
      b_.AddBox(name + ".body", p, Vector3d(length, width, 0.75), yaw, 1);
      const Vector3d back(std::cos(yaw), std::sin(yaw), 0.0);
      const Vector3d cabin = p - 0.05 * length * back + Vector3d(0, 0, 0.375 + 0.225);
      b_.AddBox(name + ".cabin", cabin, Vector3d(0.55 * length, 0.9 * width, 0.45), yaw, 1);
    }
  }

  SceneBuilder b_;
  SplitMixRandom rng_;
  const StreetLayout& L_;
  double road_edge_z_ = 0.0;  // road height at the kerb
  double top_z_ = 0.0;        // sidewalk top
  double end_x_ = 0.0, end_y_ = 0.0;
  int sidewalk_id_ = 0;
  std::string sidewalk_name_;
};

/// The rounded rectangle the route follows, as lines and left arcs from the start.
struct RouteGeometry {
  struct Segment {
    bool arc = false;
    double length = 0.0;
    Eigen::Vector2d start;  // line: start point; arc: centre
    double heading = 0.0;   // line: direction; arc: start angle around the centre
  };
  std::vector<Segment> segments;
  double loop = 0.0;
  double radius = 0.0;

  RouteGeometry() {
    const StreetLayout& L = DefaultStreetLayout();
    const double A = L.street_x + L.lane_offset, B = L.street_y + L.lane_offset;
    const double r = L.turn_radius, x_start = -50.0;
    radius = r;
    auto line = [&](Eigen::Vector2d a, double heading, double length) {
      segments.push_back({false, length, a, heading});
    };
    auto arc = [&](Eigen::Vector2d c, double angle) {
      segments.push_back({true, 0.5 * kPi * r, c, angle});
    };
    line({x_start, -B}, 0.0, A - r - x_start);
    arc({A - r, -B + r}, -0.5 * kPi);
    line({A, -B + r}, 0.5 * kPi, 2 * (B - r));
    arc({A - r, B - r}, 0.0);
    line({A - r, B}, kPi, 2 * (A - r));
    arc({-A + r, B - r}, 0.5 * kPi);
    line({-A, B - r}, -0.5 * kPi, 2 * (B - r));
    arc({-A + r, -B + r}, kPi);
    line({-A + r, -B}, 0.0, x_start + A - r);
    for (const Segment& s : segments) loop += s.length;
  }

  /// Position, heading and curvature at arc length s (taken modulo the loop).
  void At(double s, Eigen::Vector2d* p, double* heading) const {
    s = std::fmod(s, loop);
    if (s < 0) s += loop;
    for (const Segment& seg : segments) {
      if (s > seg.length && &seg != &segments.back()) {
        s -= seg.length;
        continue;
      }
      if (!seg.arc) {
        *p = seg.start + s * Eigen::Vector2d(std::cos(seg.heading), std::sin(seg.heading));
        *heading = seg.heading;
      } else {
        const double a = seg.heading + s / radius;
        *p = seg.start + radius * Eigen::Vector2d(std::cos(a), std::sin(a));
        *heading = a + 0.5 * kPi;
      }
      return;
    }
  }

  /// Arc lengths (within one loop) where the arcs start.
  std::vector<double> ArcStarts() const {
    std::vector<double> out;
    double s = 0.0;
    for (const Segment& seg : segments) {
      if (seg.arc) out.push_back(s);
      s += seg.length;
    }
    return out;
  }
};

const RouteGeometry& Route() {
  static const RouteGeometry route;
  return route;
}

Eigen::Matrix3d BodyRotation(double yaw, double pitch, double roll) {
  // Yaw about z, pitch (positive = nose up) about the left axis, roll about the forward axis.
  return (Eigen::AngleAxisd(yaw, Vector3d::UnitZ()) * Eigen::AngleAxisd(-pitch, Vector3d::UnitY()) *
          Eigen::AngleAxisd(roll, Vector3d::UnitX()))
      .toRotationMatrix();
}

}  // namespace

const StreetLayout& DefaultStreetLayout() {
  static const StreetLayout layout;
  return layout;
}

SyntheticScene MakeStreetScene(std::uint64_t seed) { return StreetBuilder(seed).Build(); }

double StreetGroundHeight(double x, double y) {
  const StreetLayout& L = DefaultStreetLayout();
  const double dx = std::min(std::abs(x - L.street_x), std::abs(x + L.street_x));
  const double dy = std::min(std::abs(y - L.street_y), std::abs(y + L.street_y));
  const double m = std::min(dx, dy);
  if (m <= L.road_half_width) return -L.camber * m;
  return -L.camber * L.road_half_width + L.kerb;
}

double StreetRouteLength(double laps) { return laps * Route().loop; }

StreetRoute::StreetRoute(const SyntheticTrajectoryConfig& config)
    : length_(StreetRouteLength(config.laps)),
      pitch_amplitude_(config.pitch_amplitude_deg * kDeg),
      roll_amplitude_(config.roll_amplitude_deg * kDeg),
      height_amplitude_(config.height_amplitude) {
  PLANESLAM_CHECK(config.speed > 0 && config.laps > 0, "street route: speed and laps must be > 0");
  // Speed: `speed` on the straights, half of it through the turns, constant 2 m/s^2 braking and
  // acceleration in between.
  const double v_max = config.speed, v_turn = 0.5 * config.speed, accel = 2.0;
  const double ramp = (v_max * v_max - v_turn * v_turn) / (2.0 * accel);
  const RouteGeometry& route = Route();
  const double arc = 0.5 * kPi * route.radius;
  // Knots (s, v) with v^2 linear between them.
  std::vector<std::pair<double, double>> knots = {{0.0, v_max}};
  for (double lap = 0; lap * route.loop < length_; ++lap) {
    for (double a : route.ArcStarts()) {
      const double s = lap * route.loop + a;
      if (s - ramp >= length_) break;
      knots.emplace_back(s - ramp, v_max);
      knots.emplace_back(s, v_turn);
      knots.emplace_back(s + arc, v_turn);
      knots.emplace_back(s + arc + ramp, v_max);
    }
  }
  knots.emplace_back(std::max(length_, knots.back().first), knots.back().second);
  double t = 0.0;
  for (std::size_t k = 0; k + 1 < knots.size(); ++k) {
    const auto [s0, v0] = knots[k];
    const auto [s1, v1] = knots[k + 1];
    if (s1 <= s0) continue;
    phases_.push_back({s0, s1, v0, v1, t});
    t += 2.0 * (s1 - s0) / (v0 + v1);
  }
  // The route ends at length_: the last phase may run past it, so the duration is the time at
  // length_.
  duration_ = 0.0;
  for (const Phase& p : phases_) {
    if (length_ <= p.s1) {
      const double a = (p.v1 * p.v1 - p.v0 * p.v0) / (2.0 * (p.s1 - p.s0));
      const double v = std::sqrt(std::max(0.0, p.v0 * p.v0 + 2.0 * a * (length_ - p.s0)));
      duration_ = p.t0 + 2.0 * (length_ - p.s0) / (p.v0 + v);
      break;
    }
  }
}

double StreetRoute::ArcLength(double t) const {
  t = std::clamp(t, 0.0, duration_);
  const Phase* p = &phases_.front();
  for (const Phase& q : phases_) {
    if (q.t0 <= t) p = &q;
  }
  const double a = (p->v1 * p->v1 - p->v0 * p->v0) / (2.0 * (p->s1 - p->s0));
  const double tau = t - p->t0;
  return std::min(p->s0 + p->v0 * tau + 0.5 * a * tau * tau, length_);
}

Pose StreetRoute::ScannerPose(double t) const {
  const double s = ArcLength(t);
  Eigen::Vector2d p = Eigen::Vector2d::Zero();
  double heading = 0.0;
  Route().At(s, &p, &heading);
  // Attitude from the ground under the four wheels (wheelbase 2.7 m, track 1.6 m).
  const Eigen::Vector2d fwd(std::cos(heading), std::sin(heading)), left(-fwd.y(), fwd.x());
  auto ground = [&](double f, double l) {
    const Eigen::Vector2d q = p + f * fwd + l * left;
    return StreetGroundHeight(q.x(), q.y());
  };
  const double fl = ground(1.35, 0.8), fr = ground(1.35, -0.8), rl = ground(-1.35, 0.8),
               rr = ground(-1.35, -0.8);
  double pitch = std::atan2(0.5 * (fl + fr) - 0.5 * (rl + rr), 2.7);
  double roll = std::atan2(0.5 * (fl + rl) - 0.5 * (fr + rr), 1.6);
  double z = 0.25 * (fl + fr + rl + rr);
  // Suspension: small oscillations with incommensurate wavelengths along the road [m].
  pitch += pitch_amplitude_ * std::sin(2 * kPi * s / 7.3);
  roll += roll_amplitude_ * std::sin(2 * kPi * s / 5.1 + 1.0);
  z += height_amplitude_ * std::sin(2 * kPi * s / 3.7 + 2.0);
  Pose T = Pose::Identity();
  T.linear() = BodyRotation(heading, pitch, roll);
  T.translation() = Vector3d(p.x(), p.y(), z) + T.linear() * Vector3d(0, 0, DefaultStreetLayout().scanner_height);
  return T;
}

}  // namespace planeslam::datasets
