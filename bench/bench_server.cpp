// Service benchmark (issue 7): latency from an image's creation (ImageEvent::created, when its PNG
// encoding finished) to its arrival at a WebSocket client, and the solver's step rate with
// 0, 1, 4, 16, 64 clients streaming one run at ~2 frames per second.
//
//   build/bench/bench_server [--size N] [--seconds S] [--threads T] [--fps F]
//                            [--clients 1,4,16,64] [--repeat R] [--image W]
//
// Everything runs in this process on real loopback sockets: a RunManager and an HttpServer as in
// `sphles serve`, and the clients on one extra thread (asynchronous Beast WebSocket reads that
// parse each image header and discard the PNG). The run renders and saves its frames in every
// phase, so the differences between phases are the cost of streaming alone.
#include <unistd.h>
#include <algorithm>
#include <atomic>
#include <boost/asio/connect.hpp>
#include <boost/asio/executor_work_guard.hpp>
#include <boost/asio/io_context.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>
#include <boost/beast/websocket.hpp>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <memory>
#include <mutex>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "control/run_manager.hpp"
#include "server/http_server.hpp"

namespace {

namespace beast = boost::beast;
namespace net = boost::asio;
namespace websocket = beast::websocket;
using tcp = net::ip::tcp;
using nlohmann::json;
using Clock = std::chrono::steady_clock;

struct Options {
  int size = 96;          // particles per side (2D Taylor-Green)
  double seconds = 10.0;  // measured wall time per phase
  int threads = 1;        // solver OpenMP threads
  double fps = 2.0;       // target images per second
  int image = 400;        // image side [px]
  std::vector<int> clients{1, 4, 16, 64};
  int repeat = 2;  // each client count measured this often
};

Options parse(int argc, char** argv) {
  Options o;
  for (int k = 1; k < argc; ++k) {
    const std::string a = argv[k];
    const auto value = [&]() -> std::string {
      if (k + 1 >= argc) {
        std::fprintf(stderr, "bench_server: %s needs a value\n", a.c_str());
        std::exit(2);
      }
      return argv[++k];
    };
    if (a == "--size") {
      o.size = std::stoi(value());
    } else if (a == "--seconds") {
      o.seconds = std::stod(value());
    } else if (a == "--threads") {
      o.threads = std::stoi(value());
    } else if (a == "--fps") {
      o.fps = std::stod(value());
    } else if (a == "--image") {
      o.image = std::stoi(value());
    } else if (a == "--repeat") {
      o.repeat = std::stoi(value());
    } else if (a == "--clients") {
      o.clients.clear();
      std::stringstream list(value());
      for (std::string item; std::getline(list, item, ',');) o.clients.push_back(std::stoi(item));
    } else {
      std::fprintf(stderr,
                   "usage: bench_server [--size N] [--seconds S] [--threads T] [--fps F] "
                   "[--image W] [--clients 1,4,16,64] [--repeat R]\n");
      std::exit(2);
    }
  }
  return o;
}

/// What every client saw in a phase.
struct Stats {
  std::mutex mutex;
  std::vector<double> latency_ms;  // image created → image arrived
  std::atomic<std::uint64_t> images{0}, bytes{0}, texts{0};
  void reset() {
    std::lock_guard lock(mutex);
    latency_ms.clear();
    images = 0;
    bytes = 0;
    texts = 0;
  }
};

/// A WebSocket client that reads everything and times images.
class Client : public std::enable_shared_from_this<Client> {
 public:
  Client(net::io_context& ioc, Stats& stats) : ws_(ioc), stats_(stats) {}

  void connect(unsigned short port, const std::string& target) {
    ws_.next_layer().connect({net::ip::make_address("127.0.0.1"), port});
    ws_.read_message_max(64u << 20);
    ws_.handshake("127.0.0.1", target);
  }
  void start() { read(); }
  void close() {
    net::post(ws_.get_executor(), [self = shared_from_this()] {
      beast::error_code ec;
      self->ws_.next_layer().shutdown(tcp::socket::shutdown_both, ec);
      self->ws_.next_layer().close(ec);
    });
  }

 private:
  void read() {
    ws_.async_read(buffer_, [self = shared_from_this()](beast::error_code ec, std::size_t n) {
      if (ec) return;
      self->on_message(n);
      self->read();
    });
  }
  void on_message(std::size_t n) {
    const auto arrived = Clock::now();
    if (ws_.got_binary()) {
      const auto* p = static_cast<const unsigned char*>(buffer_.data().data());
      const std::size_t length = (std::size_t{p[0]} << 24) | (std::size_t{p[1]} << 16) |
                                 (std::size_t{p[2]} << 8) | std::size_t{p[3]};
      const json header = json::parse(std::string(reinterpret_cast<const char*>(p) + 4, length));
      const Clock::time_point created{
          std::chrono::nanoseconds(header["created_ns"].get<std::int64_t>())};
      const double ms = std::chrono::duration<double, std::milli>(arrived - created).count();
      {
        std::lock_guard lock(stats_.mutex);
        stats_.latency_ms.push_back(ms);
      }
      ++stats_.images;
      stats_.bytes += n;
    } else {
      ++stats_.texts;
    }
    buffer_.consume(buffer_.size());
  }

  websocket::stream<tcp::socket> ws_;
  beast::flat_buffer buffer_;
  Stats& stats_;
};

/// stream.dropped of GET /api/runs/{id}: images dropped from full client queues, all clients.
std::uint64_t dropped_images(unsigned short port, const std::string& id) {
  net::io_context ioc;
  tcp::socket socket(ioc);
  socket.connect({net::ip::make_address("127.0.0.1"), port});
  beast::http::request<beast::http::empty_body> req{beast::http::verb::get, "/api/runs/" + id, 11};
  req.set(beast::http::field::host, "127.0.0.1");
  beast::http::write(socket, req);
  beast::flat_buffer buffer;
  beast::http::response<beast::http::string_body> res;
  beast::http::read(socket, buffer, res);
  return json::parse(res.body())["stream"]["dropped"].get<std::uint64_t>();
}

double percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  const std::size_t i = std::min(v.size() - 1, static_cast<std::size_t>(q * (v.size() - 1) + 0.5));
  return v[i];
}

}  // namespace

int main(int argc, char** argv) {
  const Options o = parse(argc, argv);
  const std::filesystem::path data =
      std::filesystem::temp_directory_path() / ("sphles-bench-server-" + std::to_string(getpid()));
  std::filesystem::remove_all(data);

  sphles::control::ManagerOptions m;
  m.data_directory = data;
  m.run_options.threads = o.threads;
  sphles::control::RunManager manager(m);
  sphles::server::ServerOptions s;
  s.port = 0;
  sphles::server::HttpServer server(manager, s);
  server.start();

  // A 2D Taylor-Green run that renders ω² slices (saved) with every analysis frame.
  json scene = {
      {"name", "bench"},
      {"case", "tgv2d"},
      {"particles_per_side", o.size},
      {"packing", {{"enabled", false}}},
      {"time", {{"end", 1e6}}},
      {"analysis", {{"every", 1e5}, {"products", {"slices"}}, {"slice", {{"fields", {"omega2"}}}}}},
      {"render",
       {{"fields", {"omega2"}},
        {"combined", false},
        {"save", true},
        {"width", o.image},
        {"height", o.image}}}};
  sphles::control::CreateRequest request;
  request.scene = scene;
  const auto run = manager.create(request);

  // Calibrate: simulated time per wall second, then one analysis frame every 1/fps seconds.
  const auto sample = [&] { return std::make_pair(Clock::now(), run->status()); };
  std::this_thread::sleep_for(std::chrono::seconds(2));
  auto [t0, s0] = sample();
  std::this_thread::sleep_for(std::chrono::seconds(3));
  auto [t1, s1] = sample();
  const double rate = (s1.time - s0.time) / std::chrono::duration<double>(t1 - t0).count();
  const double every = rate / o.fps;
  run->apply_changes({{"analysis", {{"every", every}}}});
  std::printf(
      "bench_server: tgv2d %d^2 particles, %d solver thread(s), %.3g simulated s per wall s; "
      "an %dx%d omega2 image every %.4g simulated s (target %.1f images/s); %.0f s per phase\n",
      o.size, o.threads, rate, o.image, o.image, every, o.fps, o.seconds);
  std::printf("server on %s, clients on 1 thread in the same process\n\n", server.url().c_str());
  Stats stats;
  net::io_context client_ioc;
  auto guard = net::make_work_guard(client_ioc);
  std::thread client_thread([&] { client_ioc.run(); });

  // One phase: n clients connected, 2 s warm-up, then o.seconds measured.
  struct Phase {
    int clients = 0;
    double steps_per_second = 0.0, images_per_client = 0.0, kib_per_image = 0.0;
    std::uint64_t dropped = 0;
    std::vector<double> latency_ms;
  };
  const auto measure = [&](int n) {
    std::vector<std::shared_ptr<Client>> clients;
    for (int k = 0; k < n; ++k) {
      auto c = std::make_shared<Client>(client_ioc, stats);
      c->connect(server.port(), "/api/runs/" + run->id() + "/stream");
      c->start();
      clients.push_back(std::move(c));
    }
    std::this_thread::sleep_for(std::chrono::seconds(2));
    stats.reset();
    const std::uint64_t dropped0 = dropped_images(server.port(), run->id());
    auto [a, sa] = sample();
    std::this_thread::sleep_for(std::chrono::duration<double>(o.seconds));
    auto [b, sb] = sample();
    Phase p;
    p.clients = n;
    const double wall = std::chrono::duration<double>(b - a).count();
    p.steps_per_second = static_cast<double>(sb.step - sa.step) / wall;
    p.dropped = dropped_images(server.port(), run->id()) - dropped0;
    {
      std::lock_guard lock(stats.mutex);
      p.latency_ms = stats.latency_ms;
    }
    const auto images = static_cast<double>(stats.images);
    p.images_per_client = n > 0 ? images / n / wall : 0.0;
    p.kib_per_image = images > 0 ? static_cast<double>(stats.bytes) / images / 1024.0 : 0.0;
    for (const auto& c : clients) c->close();
    clients.clear();
    std::this_thread::sleep_for(std::chrono::milliseconds(500));
    std::printf(
        "  phase: %2d clients  %6.1f steps/s  %5.2f images/s/client  latency median %.1f ms\n", n,
        p.steps_per_second, p.images_per_client, percentile(p.latency_ms, 0.5));
    std::fflush(stdout);
    return p;
  };

  // Interleaved with client-free phases, repeated, so that drifts of a shared machine's load
  // hit every client count alike; each count is compared with the median of all 0 phases.
  std::map<int, std::vector<Phase>> phases;
  for (int r = 0; r < o.repeat; ++r)
    for (const int n : o.clients) {
      if (n == 0) continue;
      phases[0].push_back(measure(0));
      phases[n].push_back(measure(n));
    }
  phases[0].push_back(measure(0));

  const auto median = [](std::vector<double> v) { return percentile(std::move(v), 0.5); };
  std::vector<double> base;
  for (const Phase& p : phases[0]) base.push_back(p.steps_per_second);
  const double reference = median(base);
  std::printf(
      "\nclients  steps/s (median)  vs 0 clients  images/s/client  KiB/image  "
      "latency ms: median    p95    max  dropped\n");
  for (const auto& [n, list] : phases) {
    std::vector<double> steps, latency;
    double images = 0.0, kib = 0.0;
    std::uint64_t dropped = 0;
    for (const Phase& p : list) {
      steps.push_back(p.steps_per_second);
      latency.insert(latency.end(), p.latency_ms.begin(), p.latency_ms.end());
      images += p.images_per_client / static_cast<double>(list.size());
      kib += p.kib_per_image / static_cast<double>(list.size());
      dropped += p.dropped;
    }
    const double m = median(steps);
    std::printf("%7d  %16.1f  %+11.1f%%  %15.2f  %9.1f  %17.1f  %5.1f  %5.1f  %7llu\n", n, m,
                100.0 * (m / reference - 1.0), images, kib, percentile(latency, 0.5),
                percentile(latency, 0.95),
                latency.empty() ? 0.0 : *std::max_element(latency.begin(), latency.end()),
                static_cast<unsigned long long>(dropped));
  }
  guard.reset();
  client_ioc.stop();
  client_thread.join();
  server.stop_accepting();
  manager.shutdown();
  server.stop();
  std::filesystem::remove_all(data);
  return 0;
}
