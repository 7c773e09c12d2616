// `ptmkit fit --batch JOBS.txt`: many captures in one job, each fitted by a child `ptmkit fit`
// (its own outputs committed or not, whatever the others do), handed out to the processes of
// an MPI job as they become free, or run one after another in a plain run.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

namespace ptmkit::app {

// One line of a jobs file: `LIGHTS OUTPUT [fit options...]`, words separated by blanks, a
// word with blanks in double quotes; `#` starts a comment, blank lines are skipped.
struct BatchJob {
  int line = 0;
  std::string lights;
  std::string output;
  std::vector<std::string> options;
};

// Throws ptmkit::Error naming the file and line: unreadable file, a line with fewer than two
// words, an unterminated quote, no job at all.
[[nodiscard]] std::vector<BatchJob> read_batch_jobs(const std::filesystem::path& file);

// Runs the jobs with `common` (the command line's fit options) before each line's own,
// prints a table (capture, status, seconds, residual RMS) and writes the JSON summary to
// `summary_json` if given. Returns the number of captures that failed.
int run_fit_batch(const std::filesystem::path& jobs_file, const std::vector<std::string>& common,
                  const std::string& summary_json);

}  // namespace ptmkit::app
