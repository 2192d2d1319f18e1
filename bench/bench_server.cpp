// SPDX-License-Identifier: GPL-3.0-or-later
// Service benchmark (docs/performance.md, "Server"): latency from an image's creation
// (ImageEvent::created, when its PNG encoding finished) to its arrival at a WebSocket client, and
// the solver's step rate with 0, 1, 4, 16, 64 clients streaming one run at ~2 frames per second.
//
//   build/bench/bench_server [--size N] [--seconds S] [--threads T] [--fps F]
//                            [--clients 1,4,16,64] [--repeat R] [--image W]
//
// Everything runs in this process on real loopback sockets: a RunManager and an HttpServer as in
// `sphles serve`, and the clients on one extra thread (asynchronous Beast WebSocket reads that
// parse each image header and discard the PNG). The run renders and saves its frames in every
// phase, so the differences between phases are the cost of streaming alone.
#include <pthread.h>
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
#include <fstream>
#include <map>
#include <memory>
#include <mutex>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "bench/process_time.hpp"
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

/// CPU time [s] of this process's threads, summed by thread name (/proc/self/task/*/stat).
std::map<std::string, double> thread_cpu_seconds() {
  std::map<std::string, double> cpu;
  const double tick = static_cast<double>(sysconf(_SC_CLK_TCK));
  for (const auto& task : std::filesystem::directory_iterator("/proc/self/task")) {
    std::ifstream in(task.path() / "stat");
    std::string stat;
    std::getline(in, stat);
    const std::size_t open = stat.find('('), close = stat.rfind(')');
    if (open == std::string::npos || close == std::string::npos) continue;
    const std::string name = stat.substr(open + 1, close - open - 1);
    std::istringstream rest(stat.substr(close + 2));
    std::string field;
    double utime = 0.0, stime = 0.0;
    for (int k = 3; k <= 15 && rest >> field; ++k) {
      if (k == 14) utime = std::stod(field);
      if (k == 15) stime = std::stod(field);
    }
    cpu[name] += (utime + stime) / tick;
  }
  return cpu;
}

double percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  const std::size_t i = std::min(v.size() - 1, static_cast<std::size_t>(q * (v.size() - 1) + 0.5));
  return v[i];
}

/// The middle of a sorted copy of `v` (the mean of the two middle values of an even count); 0
/// when empty.
double median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  const std::size_t m = v.size() / 2;
  return v.size() % 2 == 1 ? v[m] : 0.5 * (v[m - 1] + v[m]);
}

/// A 2D Taylor-Green run that renders ω² slices (saved) with every analysis frame.
json bench_scene(const Options& o) {
  return {
      {"name", "bench"},
      {"case", "tgv2d"},
      {"particles_per_side", o.size},
      {"kernel", {{"diameter_over_spacing", 12}}},
      {"packing", {{"enabled", false}}},
      {"time", {{"end", 1e6}}},
      {"analysis", {{"every", 1e5}, {"products", {"slices"}}, {"slice", {{"fields", {"omega2"}}}}}},
      {"render",
       {{"fields", {"omega2"}},
        {"combined", false},
        {"save", true},
        {"width", o.image},
        {"height", o.image}}}};
}

/// The run's status now and when it was taken.
std::pair<Clock::time_point, sphles::control::RunStatus> sample(const sphles::control::Run& run) {
  return std::make_pair(Clock::now(), run.status());
}

/// Calibrate: simulated time per wall second, then one analysis frame every 1/fps seconds.
void calibrate(sphles::control::Run& run, const sphles::server::HttpServer& server,
               const Options& o) {
  std::this_thread::sleep_for(std::chrono::seconds(2));
  auto [t0, s0] = sample(run);
  std::this_thread::sleep_for(std::chrono::seconds(3));
  auto [t1, s1] = sample(run);
  const double rate = (s1.time - s0.time) / std::chrono::duration<double>(t1 - t0).count();
  const double every = rate / o.fps;
  run.apply_changes({{"analysis", {{"every", every}}}});
  std::printf(
      "bench_server: tgv2d %d^2 particles, %d solver thread(s), %.3g simulated s per wall s; "
      "an %dx%d omega2 image every %.4g simulated s (target %.1f images/s); %.0f s per phase\n",
      o.size, o.threads, rate, o.image, o.image, every, o.fps, o.seconds);
  std::printf("server on %s, clients on 1 thread in the same process\n\n", server.url().c_str());
}

/// One phase: n clients connected, 2 s warm-up, then o.seconds measured.
struct Phase {
  int clients = 0;
  double steps_per_second = 0.0, images_per_client = 0.0, kib_per_image = 0.0;
  double cpu_cores = 0.0;     // CPU time of the whole process per wall second
  double io_cores = 0.0;      // of the server's I/O threads ("sphles-io")
  double client_cores = 0.0;  // of the benchmark's client thread
  std::uint64_t dropped = 0;
  std::vector<double> latency_ms;
};

/// What a phase streams from and to: the server, its run, and the clients' thread and counts.
struct Streaming {
  sphles::server::HttpServer& server;
  sphles::control::Run& run;
  net::io_context& client_ioc;
  Stats& stats;
  const Options& o;
};

Phase measure(const Streaming& s, int n) {
  std::vector<std::shared_ptr<Client>> clients;
  for (int k = 0; k < n; ++k) {
    auto c = std::make_shared<Client>(s.client_ioc, s.stats);
    c->connect(s.server.port(), "/api/runs/" + s.run.id() + "/stream");
    c->start();
    clients.push_back(std::move(c));
  }
  std::this_thread::sleep_for(std::chrono::seconds(2));
  s.stats.reset();
  const std::uint64_t dropped0 = dropped_images(s.server.port(), s.run.id());
  const double cpu0 = sphles::bench::process_cpu_seconds();
  const auto threads0 = thread_cpu_seconds();
  auto [a, sa] = sample(s.run);
  std::this_thread::sleep_for(std::chrono::duration<double>(s.o.seconds));
  auto [b, sb] = sample(s.run);
  const double cpu1 = sphles::bench::process_cpu_seconds();
  const auto threads1 = thread_cpu_seconds();
  Phase p;
  p.clients = n;
  const double wall = std::chrono::duration<double>(b - a).count();
  p.cpu_cores = (cpu1 - cpu0) / wall;
  const auto by_name = [&](const std::string& name) {
    const auto t0 = threads0.find(name), t1 = threads1.find(name);
    return t1 == threads1.end() ? 0.0 : (t1->second - (t0 == threads0.end() ? 0.0 : t0->second));
  };
  p.io_cores = by_name("sphles-io") / wall;
  p.client_cores = by_name("bench-clients") / wall;
  p.steps_per_second = static_cast<double>(sb.step - sa.step) / wall;
  p.dropped = dropped_images(s.server.port(), s.run.id()) - dropped0;
  {
    std::lock_guard lock(s.stats.mutex);
    p.latency_ms = s.stats.latency_ms;
  }
  const auto images = static_cast<double>(s.stats.images);
  p.images_per_client = n > 0 ? images / n / wall : 0.0;
  p.kib_per_image = images > 0 ? static_cast<double>(s.stats.bytes) / images / 1024.0 : 0.0;
  for (const auto& c : clients) c->close();
  clients.clear();
  std::this_thread::sleep_for(std::chrono::milliseconds(500));
  std::printf(
      "  phase: %2d clients  %6.1f steps/s  %5.2f images/s/client  latency median %5.1f ms  "
      "CPU: process %.2f, server I/O %.3f, clients %.3f cores\n",
      n, p.steps_per_second, p.images_per_client, percentile(p.latency_ms, 0.5), p.cpu_cores,
      p.io_cores, p.client_cores);
  std::fflush(stdout);
  return p;
}

/// The phases of every client count, and each one's step rate relative to the neighbouring
/// 0-client phases.
struct Phases {
  std::map<int, std::vector<Phase>> phases;
  std::map<int, std::vector<double>> ratio;  // vs the neighbouring 0-client phases
};

/// Each client count is measured between two client-free phases and compared with their mean,
/// so that the drifting load of a shared machine cancels; repeated, then the median is taken.
Phases measure_all(const Streaming& s) {
  Phases all;
  Phase before = measure(s, 0);
  all.phases[0].push_back(before);
  for (int r = 0; r < s.o.repeat; ++r)
    for (const int n : s.o.clients) {
      if (n == 0) continue;
      const Phase with = measure(s, n);
      const Phase after = measure(s, 0);
      all.phases[n].push_back(with);
      all.phases[0].push_back(after);
      const double base = 0.5 * (before.steps_per_second + after.steps_per_second);
      all.ratio[n].push_back(with.steps_per_second / base);
      before = after;
    }
  return all;
}

/// The table of every client count: medians over its phases.
void print_table(Phases& all) {
  std::printf(
      "\nclients  steps/s  vs 0 clients (median, min..max)  images/s/client  KiB/image  "
      "latency ms: median    p95    max  dropped  server I/O CPU (cores)  client CPU\n");
  for (const auto& [n, list] : all.phases) {
    std::vector<double> steps, latency;
    double images = 0.0, kib = 0.0;
    std::uint64_t dropped = 0;
    std::vector<double> io, client;
    for (const Phase& p : list) {
      io.push_back(p.io_cores);
      client.push_back(p.client_cores);
      steps.push_back(p.steps_per_second);
      latency.insert(latency.end(), p.latency_ms.begin(), p.latency_ms.end());
      images += p.images_per_client / static_cast<double>(list.size());
      kib += p.kib_per_image / static_cast<double>(list.size());
      dropped += p.dropped;
    }
    const std::vector<double>& r = all.ratio[n];
    const double change = n == 0 ? 0.0 : 100.0 * (median(r) - 1.0);
    const double lo = r.empty() ? 0.0 : 100.0 * (*std::min_element(r.begin(), r.end()) - 1.0);
    const double hi = r.empty() ? 0.0 : 100.0 * (*std::max_element(r.begin(), r.end()) - 1.0);
    std::printf(
        "%7d  %7.1f  %+8.1f%% (%+6.1f%% .. %+6.1f%%)  %15.2f  %9.1f  %17.1f  %5.1f  %5.1f  %7llu  "
        "%22.4f  %10.4f\n",
        n, median(steps), change, lo, hi, images, kib, percentile(latency, 0.5),
        percentile(latency, 0.95),
        latency.empty() ? 0.0 : *std::max_element(latency.begin(), latency.end()),
        static_cast<unsigned long long>(dropped), median(io), median(client));
  }
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

  sphles::control::CreateRequest request;
  request.scene = bench_scene(o);
  const auto run = manager.create(request);
  calibrate(*run, server, o);
  Stats stats;
  net::io_context client_ioc;
  auto guard = net::make_work_guard(client_ioc);
  std::thread client_thread([&] {
    pthread_setname_np(pthread_self(), "bench-clients");
    client_ioc.run();
  });

  Phases phases = measure_all({server, *run, client_ioc, stats, o});
  print_table(phases);
  guard.reset();
  client_ioc.stop();
  client_thread.join();
  server.stop_accepting();
  manager.shutdown();
  server.stop();
  std::filesystem::remove_all(data);
  return 0;
}
