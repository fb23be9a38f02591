// `planeslam graph optimize IN.g2o`: optimises a 3D pose graph file with the pose graph back-end
// of `planeslam run` and writes the result as g2o.
#include <cstdio>
#include <iostream>
#include <nlohmann/json.hpp>
#include <string>

#include "cli_common.hpp"
#include "command_registry.hpp"
#include "config_sections_mapping.hpp"
#include "planeslam/datasets/atomic_file.hpp"
#include "planeslam/mapping/g2o_io.hpp"
#include "planeslam/mapping/pose_graph.hpp"

namespace planeslam::app {
namespace {

std::string Number(const char* format, double v) {
  char buffer[64];
  std::snprintf(buffer, sizeof(buffer), format, v);
  return buffer;
}

class GraphCommand : public Command {
 public:
  std::string Name() const override { return "graph"; }
  std::string Summary() const override {
    return "Pose graph tools: optimise a g2o file (VERTEX_SE3:QUAT / EDGE_SE3:QUAT)";
  }
  int Order() const override { return 60; }

  void Setup(CLI::App& sub) override {
    sub.require_subcommand(1);
    optimize_ = sub.add_subcommand("optimize", "Optimise a 3D pose graph read from a g2o file");
    optimize_->add_option("input", input_, "g2o file (VERTEX_SE3:QUAT, EDGE_SE3:QUAT, FIX)")
        ->required()
        ->type_name("IN.g2o");
    optimize_->add_option("-o,--out", out_, "write the optimised graph here (g2o, atomic)")
        ->type_name("OUT.g2o");
    max_iterations_opt_ = optimize_
                              ->add_option("--max-iterations", max_iterations_,
                                           "Levenberg-Marquardt iterations at most (default: "
                                           "pose_graph.max_iterations, 200)")
                              ->check(CLI::Range(0, 100000));
    optimize_->add_option("--json", json_, "also write the figures as JSON to this file")
        ->type_name("FILE");
    optimize_->add_flag(
        "--raw-information", raw_information_,
        "use the file's information matrices as they are in our residual (2 vec(q) rotation "
        "error), like Ceres' pose_graph_3d example, instead of converting g2o's convention; for "
        "comparing figures with that example (the output keeps the file's matrices)");
    AddConfigOptions(*optimize_, options_);
    optimize_->footer(
        "Examples:\n"
        "  planeslam graph optimize parking-garage.g2o --out garage_opt.g2o\n"
        "  planeslam graph optimize run/pose_graph.g2o --json figures.json --max-iterations 50\n"
        "  planeslam graph optimize g.g2o --set pose_graph.loop_closure_loss=none\n"
        "Edges between consecutive ids are odometry, the others loop closures (robust loss\n"
        "pose_graph.loop_closure_loss). Vertices named by FIX lines are held constant, else the\n"
        "first vertex. Information is read in g2o's convention (rotation error vec(q)) and\n"
        "converted to ours (2 vec(q)): rotation block / 4, so costs equal g2o's chi2 / 2.");
    sub.footer("Examples:\n  planeslam graph optimize parking-garage.g2o --out garage_opt.g2o");
  }

  int Run() override {
    if (!optimize_->parsed()) return 1;
    Config config = LoadConfig(options_);
    auto& pg = config.Get<mapping::PoseGraphConfig>("pose_graph");
    if (max_iterations_opt_->count() > 0) pg.max_iterations = max_iterations_;
    if (MaybePrintConfig(options_, config)) return 0;

    mapping::PoseGraph graph = mapping::ReadG2o(input_);
    if (raw_information_) {
      for (auto& edge : graph.edges())
        edge.information = mapping::InformationToG2o(edge.information);
    }
    const mapping::PoseGraphResult r = mapping::OptimizePoseGraph(graph, pg);
    if (raw_information_) {
      // Exact inverse of the scaling above, so the output carries the file's matrices.
      for (auto& edge : graph.edges()) {
        edge.information = mapping::InformationFromG2o(edge.information);
      }
    }

    const std::size_t loops = graph.NumLoopClosures();
    std::cout << "input           " << input_ << "\n"
              << "vertices        " << r.num_nodes << " (" << r.num_fixed << " fixed)\n"
              << "edges           " << r.num_edges << " (" << r.num_edges - loops << " odometry, "
              << loops << " loop closures, loss " << pg.loop_closure_loss << ")\n"
              << "initial cost    " << Number("%.6e", r.initial_cost) << "\n"
              << "final cost      " << Number("%.6e", r.final_cost) << "\n"
              << "iterations      " << r.iterations << "\n"
              << "time            " << Number("%.3f", r.time_seconds) << " s\n"
              << "converged       " << (r.converged ? "yes" : "no") << " (" << r.termination << ": "
              << r.message << ")\n";

    if (!json_.empty()) {
      nlohmann::json j;
      j["input"] = input_;
      j["vertices"] = r.num_nodes;
      j["fixed_vertices"] = r.num_fixed;
      j["edges"] = r.num_edges;
      j["loop_closures"] = loops;
      j["loop_closure_loss"] = pg.loop_closure_loss;
      j["loop_closure_loss_scale"] = pg.loop_closure_loss_scale;
      j["raw_information"] = raw_information_;
      j["initial_cost"] = r.initial_cost;
      j["final_cost"] = r.final_cost;
      j["iterations"] = r.iterations;
      j["time_s"] = r.time_seconds;
      j["converged"] = r.converged;
      j["usable"] = r.usable;
      j["termination"] = r.termination;
      j["message"] = r.message;
      if (!out_.empty() && r.usable) j["output"] = out_;
      datasets::WriteFileAtomic(json_, j.dump(2) + "\n");
    }
    if (!r.usable) {
      std::cerr << "planeslam: error: " << input_ << ": optimisation failed (" << r.message
                << "); nothing written\n";
      return 1;
    }
    if (!out_.empty()) {
      mapping::WriteG2o(graph, out_);
      std::cout << "wrote           " << out_ << "\n";
    }
    return 0;
  }

 private:
  CLI::App* optimize_ = nullptr;
  CLI::Option* max_iterations_opt_ = nullptr;
  std::string input_;
  std::string out_;
  std::string json_;
  int max_iterations_ = 200;
  bool raw_information_ = false;
  ConfigOptions options_;
};

PLANESLAM_REGISTER_COMMAND(GraphCommand);

}  // namespace
}  // namespace planeslam::app
