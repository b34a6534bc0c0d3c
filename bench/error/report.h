// Error against run time, the analysis: Pareto fronts within the 1 kHz budget, whether the
// default configuration is on them, the CSV, the plots and the markdown table.
#pragma once

#include <string>
#include <vector>

#include "runner.h"

namespace idms::bench {

// Real time at 1 kHz: a simulated ms may cost at most this much compute.
inline constexpr double kBudgetUsPerMs = 1000;

struct CaseResult {
  Case c;  // c.model may be null when read back from a CSV
  int32_t atoms = 0;
  double onset_s = 0;          // first contact in the script
  double reference_cpu_s = 0;  // CPU time of the reference run
  double reference_peak_force = 0;
  int64_t reference_bytes = 0;
  int64_t reference_warnings = 0;
  std::vector<RunResult> runs;
};

// Pareto membership over the runs within the budget: run i is on the front when no other
// within-budget run is at least as fast and at least as accurate and strictly better in one.
// `error` picks the metric. Runs over the budget are never on it.
std::vector<bool> ParetoFront(const std::vector<RunResult>& runs, double RunResult::*error);

// The runs that dominate runs[i] (faster or as fast, and more accurate or as accurate).
std::vector<int> Dominators(const std::vector<RunResult>& runs, int i, double RunResult::*error);

struct ReportOptions {
  std::string out_dir;  // CSV, PNGs and the markdown land here
  Config default_config;
  bool quick = false;
  double wall_s = 0;        // whole bench, for the document
  double cpu_s = 0;         // its CPU time (user + system)
  std::string machine;      // one line: CPU model and load, for the document
  std::string curved_note;  // how the curved model was made
};

// Reads back a CSV that WriteReport wrote (to redo the plots and the document without rerunning).
bool ReadCsv(const std::string& path, std::vector<CaseResult>* cases, std::string* error);

// Writes error-vs-runtime.csv, error-vs-runtime-<model>-<script>.png per case and
// error-vs-runtime.md into out_dir; returns false with *error on failure (a missing gnuplot is
// reported and the rest still written). Prints the verdict to stdout.
bool WriteReport(const std::vector<CaseResult>& cases, const ReportOptions& options, std::string* error);

}  // namespace idms::bench
