// perch export-bvh: a recorded episode (or a reference clip) as BVH for Blender and other tools.
// perch view: serves the browser viewer (web/viewer/dist, scripts/build-viewer.sh) and one
// recording on 127.0.0.1 and prints the URL (docs/viewer.md). The HTTP server is cpp-httplib
// (Debian's libcpp-httplib-dev): threaded, HTTP/1.1-correct, range requests.
#include <chrono>
#include <csignal>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <iterator>
#include <memory>
#include <string>
#include <thread>

#include "app/commands.h"
#include "common/json_util.h"
#include "common/paths.h"
#include "motion/bvh_export.h"
#include "tasks/recording.h"
#include "tasks/task_env.h"

// Last: its macros (from zlib / brotli / OpenSSL headers) must not reach Eigen's templates.
#include <httplib.h>

namespace perch {
namespace {

httplib::Server* g_server = nullptr;
void StopServer(int) {
  if (g_server != nullptr) g_server->stop();
}

std::string ReadBytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(in)), {});
}

void RegisterExportBvh(CLI::App& root) {
  struct BvhArgs {
    std::string recording, clip, out;
    int episode = 0;
    bool force = false;
  };
  auto b = std::make_shared<BvhArgs>();
  CLI::App* ex = root.add_subcommand(
      "export-bvh",
      "Write a recorded episode (--recording) or a reference clip (--clip) as BVH: the humanoid's "
      "skeleton, metres, Y up, at the control rate (docs/viewer.md: opening it in Blender)");
  ex->add_option("--recording", b->recording, "recording from perch eval --record");
  ex->add_option("--episode", b->episode, "episode index in the recording")->capture_default_str();
  ex->add_option("--clip", b->clip, "or: a reference clip name (data/motions/NAME.json) or file");
  ex->add_option("--out", b->out, "output .bvh")->required();
  ex->add_flag("--force", b->force, "overwrite --out");
  ex->callback([b] {
    if (b->recording.empty() == b->clip.empty()) {
      throw ConfigError("export-bvh: give exactly one of --recording and --clip");
    }
    if (!b->force && std::filesystem::exists(b->out)) {
      throw ConfigError("--out " + b->out + ": exists; not overwritten (--force)");
    }
    if (!b->recording.empty()) {
      const proto::Recording rec = ReadRecording(b->recording);
      std::string humanoid = HumanoidModel::DefaultPath();
      if (!rec.config_json().empty()) {
        humanoid =
            TaskEnvConfig::FromJson(Json::parse(rec.config_json()), b->recording + ": config")
                .env.HumanoidPath();
      }
      const HumanoidModel model = HumanoidModel::Load(humanoid);
      const ReferenceMotion m = RecordedMotion(rec, b->episode, model, b->recording);
      SaveBvhFile(b->out, HumanoidMotionToBvh(model, m, rec.control_dt(), 0.0));
      std::cerr << "export-bvh: episode " << b->episode << " (" << m.num_frames() << " frames at "
                << 1.0 / rec.control_dt() << " Hz) -> " << b->out << "\n";
    } else {
      const std::string path =
          b->clip.find('/') == std::string::npos && b->clip.find(".json") == std::string::npos
              ? ResolveProjectPath("data/motions/" + b->clip + ".json")
              : b->clip;
      const HumanoidModel model = HumanoidModel::Load(HumanoidModel::DefaultPath());
      const ReferenceMotion m = ReferenceMotion::Load(path);
      SaveBvhFile(b->out, HumanoidMotionToBvh(model, m, 1.0 / 60.0, 0.0));
      std::cerr << "export-bvh: clip " << m.name() << " -> " << b->out << "\n";
    }
  });
}

void RegisterView(CLI::App& root) {
  struct ViewArgs {
    std::string recording, viewer_dir;
    int port = 8765;
    double exit_after_s = 0;
  };
  auto v = std::make_shared<ViewArgs>();
  CLI::App* view = root.add_subcommand(
      "view", "Serve the browser viewer and a recording on 127.0.0.1; prints the URL");
  view->add_option("recording", v->recording, "recording from perch eval --record")->required();
  view->add_option("--port", v->port, "port (0: any free one)")
      ->capture_default_str()
      ->check(CLI::Range(0, 65535));
  view->add_option("--viewer-dir", v->viewer_dir,
                   "the built viewer (default: web/viewer/dist; scripts/build-viewer.sh)");
  view->add_option("--exit-after", v->exit_after_s, "stop after this many seconds (tests)")
      ->check(CLI::NonNegativeNumber);
  view->callback([v] {
    ReadRecording(v->recording);  // refuse a bad file before serving it
    const std::string dir =
        v->viewer_dir.empty() ? ResolveProjectPath("web/viewer/dist") : v->viewer_dir;
    if (!std::filesystem::exists(std::filesystem::path(dir) / "index.html")) {
      throw ConfigError("viewer: " + dir +
                        "/index.html missing; build it with scripts/build-viewer.sh");
    }
    httplib::Server server;
    if (!server.set_mount_point("/", dir)) throw ConfigError("viewer: cannot serve " + dir);
    const std::string file = v->recording;
    server.Get("/recording.bin", [file](const httplib::Request&, httplib::Response& res) {
      res.set_content(ReadBytes(file), "application/octet-stream");
      res.set_header("Cache-Control", "no-store");
    });
    int port = v->port;
    if (port == 0) {
      port = server.bind_to_any_port("127.0.0.1");
    } else if (!server.bind_to_port("127.0.0.1", port)) {
      throw ConfigError("--port " + std::to_string(port) + ": cannot bind 127.0.0.1 (in use?)");
    }
    if (port <= 0) throw ConfigError("--port: cannot bind 127.0.0.1");
    std::cout << "http://127.0.0.1:" << port << "/?file=/recording.bin" << std::endl;
    std::cerr << "view: serving " << dir << " and " << file << "; Ctrl-C to stop\n";
    g_server = &server;
    std::signal(SIGINT, StopServer);
    std::signal(SIGTERM, StopServer);
    std::unique_ptr<std::thread> timer;
    if (v->exit_after_s > 0) {
      timer = std::make_unique<std::thread>([&server, s = v->exit_after_s] {
        std::this_thread::sleep_for(std::chrono::duration<double>(s));
        server.stop();
      });
    }
    server.listen_after_bind();
    if (timer) timer->detach();  // may still be sleeping after Ctrl-C; the process ends anyway
    g_server = nullptr;
  });
}

}  // namespace

void RegisterViewCommands(CLI::App& root, CLI::App& /*bench*/) {
  RegisterExportBvh(root);
  RegisterView(root);
}

}  // namespace perch
