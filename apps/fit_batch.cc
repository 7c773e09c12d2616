#include "fit_batch.h"

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <limits>
#include <string>

#include <nlohmann/json.hpp>

#include "mpi_collective.h"
#include "ptmkit/core/atomic_file.h"
#include "ptmkit/core/error.h"
#include "ptmkit/core/limits.h"

namespace ptmkit::app {

namespace fs = std::filesystem;

namespace {

// Splits a line into words: blanks separate, double quotes group (no escapes inside).
std::vector<std::string> words_of(const std::string& line, const fs::path& file, int line_no) {
  std::vector<std::string> out;
  std::string word;
  bool in_word = false, quoted = false;
  for (const char c : line) {
    if (quoted) {
      if (c == '"') {
        quoted = false;
      } else {
        word += c;
      }
    } else if (c == '"') {
      quoted = true;
      in_word = true;
    } else if (c == '#') {
      break;
    } else if (c == ' ' || c == '\t' || c == '\r') {
      if (in_word) out.push_back(word);
      word.clear();
      in_word = false;
    } else {
      word += c;
      in_word = true;
    }
  }
  if (quoted) throw Error(where(file, line_no) + ": a quote is not closed");
  if (in_word) out.push_back(word);
  return out;
}

// The last non-empty line of a child's stderr: its error message.
std::string last_line(const std::string& text) {
  std::size_t end = text.find_last_not_of("\r\n");
  if (end == std::string::npos) return "";
  const std::size_t start = text.rfind('\n', end);
  return text.substr(start == std::string::npos ? 0 : start + 1,
                     end - (start == std::string::npos ? 0 : start + 1) + 1);
}

}  // namespace

std::vector<BatchJob> read_batch_jobs(const fs::path& file) {
  checked_input_size(file, kMaxTextFileBytes, "jobs file");
  std::ifstream in(file);
  if (!in) throw Error(where(file) + ": cannot open the jobs file");
  std::vector<BatchJob> jobs;
  std::string line;
  int line_no = 0;
  while (std::getline(in, line)) {
    ++line_no;
    std::vector<std::string> w = words_of(line, file, line_no);
    if (w.empty()) continue;
    if (w.size() < 2) {
      throw Error(where(file, line_no) + ": expected LIGHTS OUTPUT [fit options], got '" +
                  excerpt(line) + "'");
    }
    BatchJob job;
    job.line = line_no;
    job.lights = w[0];
    job.output = w[1];
    job.options.assign(w.begin() + 2, w.end());
    jobs.push_back(std::move(job));
  }
  if (in.bad()) throw Error(where(file) + ": cannot read the jobs file");
  if (jobs.empty()) throw Error(where(file) + ": no jobs (one capture per line: LIGHTS OUTPUT)");
  return jobs;
}

int run_fit_batch(const fs::path& jobs_file, const std::vector<std::string>& common,
                  const std::string& summary_json) {
  const MpiSession* mpi = mpi_session();
  Collective* peers = mpi != nullptr ? mpi->collective() : nullptr;
  const bool lead = peers == nullptr || peers->rank() == 0;
  // Every process reads the file (the same on all): a bad file stops all before any work.
  const std::vector<BatchJob> jobs = read_batch_jobs(jobs_file);
  std::vector<std::vector<std::string>> commands;
  for (const BatchJob& j : jobs) {
    std::vector<std::string> args{"fit", j.lights, "-o", j.output};
    args.insert(args.end(), common.begin(), common.end());
    args.insert(args.end(), j.options.begin(), j.options.end());
    commands.push_back(std::move(args));
  }
  if (lead) {
    std::printf("fit --batch: %zu captures, %d process%s\n", jobs.size(),
                peers != nullptr ? peers->size() : 1,
                peers != nullptr && peers->size() > 1 ? "es" : "");
    std::fflush(stdout);
  }
  std::size_t finished = 0;
  const std::vector<ChildResult> results =
      run_children(commands, peers, [&](std::size_t i, const ChildResult& r) {
        ++finished;
        std::printf("[%zu/%zu] %s: %s (%.1f s)\n", finished, jobs.size(), jobs[i].lights.c_str(),
                    r.exit_code == 0 ? "ok" : "failed", r.seconds);
        std::fflush(stdout);
      });
  // No collective follows: a failure from here on is this process's own.
  if (peers != nullptr) peers->finish();
  if (!lead) return 0;

  // The summary: a table, and the JSON.
  nlohmann::json summary = nlohmann::json::array();
  int failed = 0;
  std::printf("\n%-40s %-7s %9s %13s  %s\n", "capture", "status", "seconds", "residual_rms", "");
  for (std::size_t i = 0; i < jobs.size(); ++i) {
    const ChildResult& r = results[i];
    double rms = std::numeric_limits<double>::quiet_NaN();
    nlohmann::json entry = {{"line", jobs[i].line},
                            {"lights", jobs[i].lights},
                            {"output", jobs[i].output},
                            {"exit_code", r.exit_code},
                            {"seconds", r.seconds}};
    // From the child's summary line ("residual rms X grey"): the child may have run on
    // another machine.
    const std::size_t at = r.out.find("residual rms ");
    if (at != std::string::npos) rms = std::atof(r.out.c_str() + at + 13);
    const bool ok = r.exit_code == 0;
    if (!ok) ++failed;
    entry["status"] = ok ? "ok" : "failed";
    if (!std::isnan(rms) && ok) entry["residual_rms_grey"] = rms;
    const std::string message = ok ? "" : last_line(r.err);
    if (!ok) entry["error"] = message;
    summary.push_back(entry);
    char rms_text[32] = "-";
    if (ok && !std::isnan(rms)) std::snprintf(rms_text, sizeof rms_text, "%.3f", rms);
    std::printf("%-40s %-7s %9.2f %13s  %s\n", jobs[i].lights.c_str(), ok ? "ok" : "failed",
                r.seconds, rms_text, message.c_str());
  }
  std::printf("%zu captures: %zu ok, %d failed\n", jobs.size(), jobs.size() - failed, failed);
  if (!summary_json.empty()) {
    const nlohmann::json doc = {{"jobs_file", jobs_file.string()},
                                {"processes", peers != nullptr ? peers->size() : 1},
                                {"captures", summary},
                                {"failed", failed}};
    // Written even when captures failed (the command then fails, and its other outputs with
    // it: here there are none).
    const OutputTransaction::Immediate now;
    write_file_atomic(summary_json, doc.dump(2) + "\n");
  }
  return failed;
}

}  // namespace ptmkit::app
