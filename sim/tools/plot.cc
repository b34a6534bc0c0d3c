// PlotPng: writes a gnuplot script for a PlotSpec and runs gnuplot on it (posix_spawnp, stderr
// captured so a failure says what gnuplot said).
#include "plot.h"

#include <fcntl.h>
#include <spawn.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>

extern char** environ;

namespace idms::tool {
namespace {

// A gnuplot single-quoted string: no escapes inside except '' for a quote.
std::string Quote(const std::string& text) {
  std::string out = "'";
  for (char c : text) out += c == '\'' ? std::string("''") : std::string(1, c);
  return out + "'";
}

std::string Num(double value) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.17g", value);
  return buf;
}

// 1-based index of `name` in the CSV header of `path`, or 0 with *error set.
int ColumnIndex(const std::string& path, const std::string& name, std::string* error) {
  std::ifstream in(path);
  std::string header;
  if (!in || !std::getline(in, header)) {
    *error = "cannot read the header of " + path;
    return 0;
  }
  if (!header.empty() && header.back() == '\r') header.pop_back();
  std::stringstream fields(header);
  std::string field;
  for (int index = 1; std::getline(fields, field, ','); ++index) {
    if (field == name) return index;
  }
  *error = "no column '" + name + "' in " + path + " (header: " + header + ")";
  return 0;
}

// The `plot` clause of one series; inline points become datablock $d<i> written to `blocks`.
bool SeriesClause(const PlotSeries& s, int i, std::string* blocks, std::string* clause, std::string* error) {
  std::string source, using_spec;
  if (s.csv_path.empty()) {
    // Inline data: a datablock, comma-separated like the files.
    const std::string name = "$d" + std::to_string(i);
    *blocks += name + " << EOD\n";
    for (const auto& p : s.points) *blocks += Num(p[0]) + "," + Num(p[1]) + "\n";
    *blocks += "EOD\n";
    source = name;
    using_spec = "1:2";
  } else {
    // File data: resolve header names to column numbers and skip the header row.
    const int x = ColumnIndex(s.csv_path, s.x_column, error);
    const int y = x ? ColumnIndex(s.csv_path, s.y_column, error) : 0;
    if (!x || !y) return false;
    using_spec = std::to_string(x) + ":" + std::to_string(y);
    if (!s.color_column.empty() || !s.label_column.empty()) {
      const bool label = !s.label_column.empty();
      const int c = ColumnIndex(s.csv_path, label ? s.label_column : s.color_column, error);
      if (!c) return false;
      using_spec += label ? ":(stringcolumn(" + std::to_string(c) + "))" : ":" + std::to_string(c);
    }
    source = Quote(s.csv_path) + " skip 1";
  }
  // Style: labels replace the style; a colour column drives the palette.
  std::string with = s.label_column.empty() ? s.style : "labels";
  if (!s.options.empty()) with += " " + s.options;
  if (!s.color_column.empty() && s.label_column.empty()) with += " lc palette";
  *clause =
      source + " using " + using_spec + " with " + with + (s.title.empty() ? " notitle" : " title " + Quote(s.title));
  return true;
}

// The whole script: terminal and axes, datablocks, one plot command.
bool BuildScript(const PlotSpec& spec, const std::string& png_path, std::string* script, std::string* error) {
  std::string head, blocks, plot;
  head += "set terminal pngcairo size " + std::to_string(spec.width_px) + "," + std::to_string(spec.height_px) +
          " noenhanced font 'sans,11'\n";
  head += "set output " + Quote(png_path) + "\n";
  head += "set datafile separator ','\n";
  head += "set grid\n";
  head += "set key " + spec.key + "\n";
  if (!spec.title.empty()) head += "set title " + Quote(spec.title) + "\n";
  if (!spec.x_label.empty()) head += "set xlabel " + Quote(spec.x_label) + "\n";
  if (!spec.y_label.empty()) head += "set ylabel " + Quote(spec.y_label) + "\n";
  if (!spec.color_label.empty()) head += "set cblabel " + Quote(spec.color_label) + "\n";
  head += "set autoscale cbfix\n";
  if (spec.equal_aspect) head += "set size ratio -1\n";
  if (spec.log_x) head += "set logscale x\n";
  if (spec.log_y) head += "set logscale y\n";
  if (spec.x_range) head += "set xrange [" + Num((*spec.x_range)[0]) + ":" + Num((*spec.x_range)[1]) + "]\n";
  if (spec.y_range) head += "set yrange [" + Num((*spec.y_range)[0]) + ":" + Num((*spec.y_range)[1]) + "]\n";
  // A perceptually uniform palette (viridis stops) for colour-coded series.
  head += "set palette defined (0 '#440154', 1 '#3b528b', 2 '#21918c', 3 '#5ec962', 4 '#fde725')\n";
  for (const std::string& line : spec.preamble) head += line + "\n";
  if (spec.series.empty()) {
    *error = "nothing to plot";
    return false;
  }
  for (size_t i = 0; i < spec.series.size(); ++i) {
    std::string clause;
    if (!SeriesClause(spec.series[i], static_cast<int>(i), &blocks, &clause, error)) return false;
    plot += (i == 0 ? "plot " : ", \\\n     ") + clause;
  }
  *script = head + blocks + plot + "\n";
  return true;
}

// Runs `program script_path` with stdin and stdout on /dev/null; returns its exit status (or
// -1 with *error set when it cannot start) and its stderr in *stderr_text.
int RunGnuplot(const std::string& program, const std::string& script_path, std::string* stderr_text,
               std::string* error) {
  int fds[2];
  if (pipe(fds) != 0) {
    *error = std::string("pipe: ") + std::strerror(errno);
    return -1;
  }
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, 0, "/dev/null", O_RDONLY, 0);
  posix_spawn_file_actions_addopen(&actions, 1, "/dev/null", O_WRONLY, 0);
  posix_spawn_file_actions_adddup2(&actions, fds[1], 2);
  posix_spawn_file_actions_addclose(&actions, fds[0]);
  posix_spawn_file_actions_addclose(&actions, fds[1]);
  std::string arg0 = program, arg1 = script_path;
  char* argv[] = {arg0.data(), arg1.data(), nullptr};
  pid_t pid = 0;
  const int rc = posix_spawnp(&pid, program.c_str(), &actions, nullptr, argv, environ);
  posix_spawn_file_actions_destroy(&actions);
  close(fds[1]);
  if (rc != 0) {
    close(fds[0]);
    *error = rc == ENOENT ? "gnuplot not found (tried '" + program +
                                "'; install the Debian package gnuplot-nox, or point IDMS_GNUPLOT at it)"
                          : "cannot start " + program + ": " + std::strerror(rc);
    return -1;
  }
  // Drain stderr until gnuplot exits, then reap it.
  char buf[4096];
  for (ssize_t n; (n = read(fds[0], buf, sizeof buf)) != 0;) {
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) break;
    stderr_text->append(buf, static_cast<size_t>(n));
  }
  close(fds[0]);
  int status = 0;
  while (waitpid(pid, &status, 0) < 0 && errno == EINTR) {
  }
  return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + (WIFSIGNALED(status) ? WTERMSIG(status) : 0);
}

// The last few non-empty lines of gnuplot's stderr, joined on one line.
std::string Tail(const std::string& text) {
  std::vector<std::string> lines;
  std::stringstream in(text);
  for (std::string line; std::getline(in, line);) {
    if (line.find_first_not_of(" \t^") != std::string::npos) lines.push_back(line);
  }
  std::string out;
  for (size_t i = lines.size() > 3 ? lines.size() - 3 : 0; i < lines.size(); ++i)
    out += (out.empty() ? "" : " | ") + lines[i];
  return out.empty() ? "no message" : out;
}

}  // namespace

bool PlotPng(const PlotSpec& spec, const std::string& png_path, std::string* error) {
  // Script first, so a missing column is reported without running anything.
  std::string script;
  if (!BuildScript(spec, png_path, &script, error)) return false;

  // Into a private temporary file that gnuplot reads by name.
  std::string script_path = (std::filesystem::temp_directory_path() / "idms-plot-XXXXXX.gp").string();
  const int fd = mkstemps(script_path.data(), 3);
  if (fd < 0) {
    *error = "cannot create a temporary gnuplot script: " + std::string(std::strerror(errno));
    return false;
  }
  const bool written = write(fd, script.data(), script.size()) == static_cast<ssize_t>(script.size());
  close(fd);
  if (!written) {
    std::remove(script_path.c_str());
    *error = "cannot write the temporary gnuplot script " + script_path;
    return false;
  }

  // Run it; a stale PNG must not pass for a fresh one.
  std::remove(png_path.c_str());
  const char* env_program = std::getenv("IDMS_GNUPLOT");
  const std::string program = env_program && *env_program ? env_program : "gnuplot";
  std::string stderr_text;
  const int status = RunGnuplot(program, script_path, &stderr_text, error);
  std::remove(script_path.c_str());
  if (status < 0) return false;
  if (status != 0) {
    *error = "gnuplot failed (exit " + std::to_string(status) + "): " + Tail(stderr_text);
    return false;
  }
  struct stat st {};
  if (stat(png_path.c_str(), &st) != 0 || st.st_size == 0) {
    *error = "gnuplot wrote no " + png_path + ": " + Tail(stderr_text);
    return false;
  }
  return true;
}

}  // namespace idms::tool
