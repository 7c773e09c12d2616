// ptmkit view FILE|DIR [--port P]: serves the web viewer on 127.0.0.1 only. A web folder is
// served as it is; a .ptm or .rti is exported first to a temporary folder (removed on exit).
// The viewer's own files always come from this binary, so a folder exported elsewhere (with
// or without an index.html of its own) opens in this viewer. HTTP range requests are
// answered (cpp-httplib). Stops on SIGINT or SIGTERM, or after --exit-after-seconds.
#include <signal.h>
#include <stdlib.h>
#include <time.h>

#include <cerrno>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>
#include <thread>

#include "commands.h"
#include "ptmkit/core/error.h"
#include "ptmkit/texture/web_export.h"

// After the Eigen headers (commands.h): <resolv.h>, which httplib includes, defines _res.
#include <httplib.h>  // NOLINT(build/include_order)

namespace fs = std::filesystem;

namespace ptmkit::app {

namespace {

struct ViewArgs {
  std::string input;
  int port = 8080;
  double exit_after_seconds = 0.0;
  WebExportArgs web;
};

// A private temporary folder, removed with everything in it on destruction.
class TempDir {
 public:
  TempDir() {
    std::string pattern = (fs::temp_directory_path() / "ptmkit-view-XXXXXX").string();
    if (mkdtemp(pattern.data()) == nullptr) {
      throw Error(pattern + ": cannot create a temporary folder: " + std::strerror(errno));
    }
    path_ = pattern;
  }
  ~TempDir() {
    std::error_code ec;
    fs::remove_all(path_, ec);
  }
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;
  [[nodiscard]] const fs::path& path() const { return path_; }

 private:
  fs::path path_;
};

void run_view(const ViewArgs& args) {
  if (args.exit_after_seconds < 0.0) throw Error("--exit-after-seconds must be >= 0");
  std::error_code ec;
  fs::path dir;
  std::unique_ptr<TempDir> temp;
  if (fs::is_directory(args.input, ec)) {
    if (!fs::exists(fs::path(args.input) / "info.json", ec)) {
      throw Error(args.input +
                  ": no info.json: not a web folder (give a web export, a .ptm or an "
                  "HSH .rti)");
    }
    dir = args.input;
    if (!args.web.normals.empty() || args.web.layout != "image" ||
        args.web.options.pixel_size_mm != 0.0) {
      std::fprintf(stderr,
                   "ptmkit: warning: --layout, --normals and --pixel-size-mm apply to a .ptm or "
                   ".rti converted on the fly; %s is served as it is\n",
                   args.input.c_str());
    }
  } else {
    temp = std::make_unique<TempDir>();
    dir = temp->path() / "export";
    texture::WebExportOptions options = args.web.resolved();
    options.viewer = false;  // served from the binary
    const texture::WebExportReport r = export_texture_to_web(args.input, dir, options);
    std::printf("converted %s: %s\n", args.input.c_str(), r.brief().c_str());
  }

  // SIGINT and SIGTERM are waited for below, not handled asynchronously: block them before
  // the server's threads start (they inherit the mask).
  sigset_t stop_signals;
  sigemptyset(&stop_signals);
  sigaddset(&stop_signals, SIGINT);
  sigaddset(&stop_signals, SIGTERM);
  pthread_sigmask(SIG_BLOCK, &stop_signals, nullptr);

  httplib::Server server;
  server.set_file_extension_and_mimetype_mapping("dzi", "application/xml");
  server.set_file_extension_and_mimetype_mapping("json", "application/json");
  server.set_file_extension_and_mimetype_mapping("js", "text/javascript");
  if (!server.set_mount_point("/", dir.string())) {
    throw Error(dir.string() + ": cannot serve this folder");
  }
  server.set_pre_routing_handler([](const httplib::Request& req, httplib::Response& res) {
    std::string name = req.path == "/" ? "index.html" : req.path.substr(1);
    for (const auto& f : texture::web_viewer_files()) {
      if (name == f.name) {
        const bool js = name.ends_with(".js"), css = name.ends_with(".css");
        res.set_content(std::string(f.contents), js    ? "text/javascript"
                                                 : css ? "text/css"
                                                       : "text/html; charset=utf-8");
        res.set_header("Cache-Control", "no-cache");
        return httplib::Server::HandlerResponse::Handled;
      }
    }
    if (req.path == "/favicon.ico") {  // none: answered, so browsers do not log a 404
      res.status = 204;
      return httplib::Server::HandlerResponse::Handled;
    }
    return httplib::Server::HandlerResponse::Unhandled;
  });
  int port = args.port;
  if (port == 0) {
    port = server.bind_to_any_port("127.0.0.1");
    if (port < 0) throw Error("cannot listen on 127.0.0.1 (no free port)");
  } else if (!server.bind_to_port("127.0.0.1", port)) {
    throw Error("cannot listen on 127.0.0.1:" + std::to_string(port) +
                " (in use? try --port 0 for any free port)");
  }
  std::thread worker([&server] { server.listen_after_bind(); });
  std::printf("serving %s at http://127.0.0.1:%d/ (Ctrl-C stops)\n", dir.string().c_str(), port);
  std::fflush(stdout);

  const auto deadline =
      std::chrono::steady_clock::now() + std::chrono::duration<double>(args.exit_after_seconds);
  for (;;) {
    timespec wait{0, 200'000'000};
    siginfo_t info;
    const int sig = sigtimedwait(&stop_signals, &info, &wait);
    if (sig == SIGINT || sig == SIGTERM) break;
    if (args.exit_after_seconds > 0.0 && std::chrono::steady_clock::now() >= deadline) break;
    if (!server.is_running() && sig < 0 && errno == EAGAIN) {
      // listen_after_bind returned on its own: a socket error.
      worker.join();
      throw Error("the server stopped unexpectedly on 127.0.0.1:" + std::to_string(port));
    }
  }
  server.stop();
  worker.join();
  pthread_sigmask(SIG_UNBLOCK, &stop_signals, nullptr);
  std::printf("stopped\n");
}

}  // namespace

void add_view_command(CLI::App& root) {
  auto args = std::make_shared<ViewArgs>();
  CLI::App* cmd = root.add_subcommand(
      "view",
      "Serve the WebGL2 viewer on 127.0.0.1 (this machine only) and print its address: a web "
      "folder as it is, or a .ptm / HSH .rti exported on the fly to a temporary folder (removed "
      "on exit). HTTP range requests are answered. Stops on Ctrl-C or SIGTERM");
  cmd->add_option("input", args->input, "Web folder (with info.json), .ptm or HSH .rti")
      ->required();
  cmd->add_option("--port", args->port, "TCP port on 127.0.0.1; 0 = any free port")
      ->check(CLI::Range(0, 65535))
      ->capture_default_str();
  cmd->add_option("--exit-after-seconds", args->exit_after_seconds,
                  "Stop after this many seconds (0 = run until stopped; for scripts and tests)")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  add_web_export_flags(cmd, &args->web);
  cmd->callback([args] { run_view(*args); });
}

}  // namespace ptmkit::app
