// SPDX-License-Identifier: GPL-3.0-or-later
// The service survives its users (the HTTP/WebSocket layer): large analysis products, running out
// of memory, read-only clients and slowloris sockets filling the connection table, histories longer
// than one answer, malformed WebSocket handshakes. Real servers on loopback ports, real runs, real
// sockets; limits are lowered through ServerOptions so that each test takes seconds.
#include <sys/resource.h>

#include <atomic>
#include <mutex>

#include "analysis/timeseries.hpp"
#include "server_test_support.hpp"

namespace {

using namespace sphles_server_test;

/// A 32² run whose statistics carry a bins² histogram (a 10⁸-count one made the server build a
/// 3 GB document per reader, and three readers at once ended in std::terminate).
json binned_scene(int bins, double end_time, int particles = 32) {
  json scene = tiny_scene(end_time, "bins");
  scene["particles_per_side"] = particles;
  scene["analysis"] = {
      {"every", 0.1}, {"products", {"energy", "sfs_stats"}}, {"histogram_bins", bins}};
  return scene;
}

/// Writes rows of the solver's time-series format (step k at t = k·1e-3, e_v = 0.25 - k·1e-9):
/// `rows` of them, or with rows = 0 until the file passes `min_bytes`. Returns the row count.
std::uint64_t write_timeseries(const fs::path& file, std::uint64_t rows,
                               std::size_t min_bytes = 0) {
  std::ofstream out(file, std::ios::binary);
  out << sphles::analysis::TimeSeriesWriter::kHeader << "\n";
  std::array<char, 256> row{};
  std::size_t bytes = 0;
  std::uint64_t step = 0;
  for (; rows ? step < rows : bytes <= min_bytes; ++step) {
    const int n =
        std::snprintf(row.data(), row.size(), "%.17g,%llu,%.17g,%.17g,%.17g,%.17g,%.17g\n",
                      static_cast<double>(step) * 1e-3, static_cast<unsigned long long>(step), 1e-3,
                      0.25 - static_cast<double>(step) * 1e-9, 1e-6, 1e-3, 1.0);
    out.write(row.data(), n);
    bytes += static_cast<std::size_t>(n);
  }
  return step;
}

json without_type(json message) {
  message.erase("type");
  return message;
}

/// GET on a raw socket, reading the body away without keeping it: status, Content-Length and
/// the bytes that arrived after the header (for bodies too large to hold in a test).
struct Counted {
  int status = 0;
  std::size_t content_length = 0, body_bytes = 0;
  std::string head;  // status line and headers
};
Counted get_counted(unsigned short port, const std::string& target) {
  net::io_context ioc;
  tcp::socket socket(ioc);
  socket.connect({net::ip::make_address("127.0.0.1"), port});
  set_socket_timeout(socket, 30s);
  const std::string request =
      "GET " + target + " HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n\r\n";
  net::write(socket, net::buffer(request));
  Counted c;
  std::array<char, 1 << 16> chunk{};
  beast::error_code ec;
  bool in_body = false;
  while (true) {
    const std::size_t n = socket.read_some(net::buffer(chunk), ec);
    if (in_body) {
      c.body_bytes += n;
    } else {
      c.head.append(chunk.data(), n);
      if (const std::size_t end = c.head.find("\r\n\r\n"); end != std::string::npos) {
        c.body_bytes = c.head.size() - end - 4;
        c.head.resize(end);
        in_body = true;
      }
    }
    if (ec) break;
  }
  c.status = status_of(c.head);
  std::string lower = c.head;
  for (char& ch : lower) ch = static_cast<char>(std::tolower(static_cast<unsigned char>(ch)));
  if (const std::size_t at = lower.find("content-length: "); at != std::string::npos)
    c.content_length = std::stoull(lower.substr(at + 16));
  return c;
}

/// Virtual memory of this process now, once it has stopped changing.
std::size_t stable_vm_bytes() {
  const auto read = [] {
    std::ifstream status("/proc/self/status");
    std::string line;
    while (std::getline(status, line))
      if (line.rfind("VmSize:", 0) == 0) return std::stoull(line.substr(7)) << 10;
    return 0ull;
  };
  std::size_t previous = read();
  for (int k = 0; k < 50; ++k) {
    std::this_thread::sleep_for(100ms);
    const std::size_t now = read();
    if (now == previous) return now;
    previous = now;
  }
  return previous;
}

/// An upgrade request with the given extra header lines (each ending in \r\n), answered raw.
std::string raw_upgrade(unsigned short port, const std::string& target,
                        const std::string& headers) {
  return raw_exchange(port,
                      "GET " + target +
                          " HTTP/1.1\r\nConnection: Upgrade\r\nUpgrade: websocket\r\n" + headers +
                          "\r\n",
                      true, 5s);
}

const std::string kGoodKey = "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n";

void expect_raw_error(const std::string& raw, int status, const std::string& field) {
  EXPECT_EQ(status_of(raw), status) << raw;
  EXPECT_NE(raw.find("Content-Type: application/json"), std::string::npos) << raw;
  const json body = json::parse(body_of(raw), nullptr, false);
  ASSERT_FALSE(body.is_discarded()) << "not JSON: " << raw;
  EXPECT_EQ(body["error"]["status"], status) << raw;
  EXPECT_EQ(body["error"]["field"], field) << raw;
  EXPECT_FALSE(body["error"]["message"].get<std::string>().empty());
}

// =============================================================================================
// Products larger than a response may be, and running out of memory.

TEST(ServerLimits, LargeProductsAnswer507AndSmallOnesAreSharedByAllReaders) {
  // A 256² histogram (the largest a scene may ask for) needs at least 128 KiB of JSON.
  constexpr std::size_t kLimit = 64u << 10;
  TestServer server(scratch("products") / "data", "", 3,
                    [&](ServerOptions& o) { o.responses.max_bytes = kLimit; });
  const Api api{server.port()};
  const std::string big = api.create({{"scene", binned_scene(256, 0.3)}});
  ASSERT_TRUE(wait_until([&] { return api.run(big)["state"] == "finished"; }, 120s));

  // Concurrent readers: each gets the documented error at once (nothing is built).
  std::vector<std::thread> readers;
  std::mutex mutex;
  std::vector<Reply> replies;
  for (int k = 0; k < 8; ++k)
    readers.emplace_back([&] {
      Reply r = api.get("/api/runs/" + big + "/statistics");
      std::lock_guard lock(mutex);
      replies.push_back(std::move(r));
    });
  for (std::thread& t : readers) t.join();
  for (const Reply& r : replies) {
    expect_error(r, 507);
    const std::string message = r.body_json()["error"]["message"];
    EXPECT_NE(message.find(std::to_string(kLimit)), std::string::npos) << message;
    EXPECT_NE(message.find("histogram_bins"), std::string::npos) << message;
  }

  // A running run with the same bins: its stream says so per frame and goes on.
  const std::string live = api.create({{"scene", binned_scene(256, 1000.0, 16)}});
  {
    std::vector<std::unique_ptr<WsClient>> clients;
    for (int k = 0; k < 4; ++k)
      clients.push_back(std::make_unique<WsClient>(server.port(), "/api/runs/" + live + "/stream"));
    for (auto& c : clients) {
      const json error = c->read_type("error", 60s).text();
      EXPECT_EQ(error["error"]["status"], 507) << error;
      c->read_type("metrics");
    }
  }
  ASSERT_EQ(api.post("/api/runs/" + live + "/stop").status, 200);

  // Below the limit: the stream's statistics message is the GET body plus "type".
  const std::string small = api.create({{"scene", binned_scene(50, 0.3)}, {"start", false}});
  WsClient ws(server.port(), "/api/runs/" + small + "/stream");
  ASSERT_EQ(ws.read().text()["type"], "hello");
  ASSERT_EQ(api.post("/api/runs/" + small + "/start").status, 200);
  std::map<std::uint64_t, json> streamed;  // statistics messages by step
  const auto collect = [&](const WsMessage& m) {
    if (m.binary) return json();
    json j = m.text();
    if (j["type"] == "statistics") streamed[j["step"].get<std::uint64_t>()] = j;
    return j;
  };
  ws.read_until(
      [&](const WsMessage& m) {
        const json j = collect(m);
        return j.is_object() && j["type"] == "state" && j["state"] == "finished";
      },
      120s);
  const Reply got = api.get("/api/runs/" + small + "/statistics");
  ASSERT_EQ(got.status, 200) << got.body;
  const std::uint64_t step = got.body_json()["step"];
  if (!streamed.contains(step))
    ws.read_until([&](const WsMessage& m) {
      collect(m);
      return streamed.contains(step);
    });
  ASSERT_TRUE(streamed.contains(step));
  EXPECT_EQ(got.body_json(), without_type(streamed[step]));
  EXPECT_EQ(got.body_json()["joint"]["counts"].size(), 50u * 50u);
  EXPECT_EQ(api.get("/api/health").status, 200);
}

/// The process's address space is limited (RLIMIT_AS) while a large response is asked for: a
/// time series of 40 MB of CSV, 27 MB of JSON (more than any malloc arena holds, so its JSON must
/// be mapped anew; scene limits keep analysis products far below that since the histogram bound).
/// With 16 MB to spare the server answers 503 and keeps running; with 800 MB it answers in full. (A
/// 6000² histogram's nlohmann document needed 1.2 GB and, failing, terminated the process from
/// its noexcept destructor.)
TEST(ServerLimits, OutOfMemoryAnswers503AndNeverTerminates) {
  TestServer server(scratch("memory") / "data", "", 2,
                    [](ServerOptions& o) { o.responses.max_bytes = std::size_t{1} << 30; });
  const Api api{server.port()};
  const std::string id = api.create({{"scene", tiny_scene()}, {"start", false}});
  const std::uint64_t rows =
      write_timeseries(server.data_directory / "runs" / id / "timeseries.csv", 0, 40u << 20);
  const std::string target = "/api/runs/" + id + "/timeseries";

  rlimit unlimited{};
  ASSERT_EQ(getrlimit(RLIMIT_AS, &unlimited), 0);
  const auto limited_to = [&](std::size_t spare) {
    rlimit limited = unlimited;
    limited.rlim_cur = stable_vm_bytes() + spare;
    return setrlimit(RLIMIT_AS, &limited) == 0;
  };

  ASSERT_TRUE(limited_to(16u << 20));
  const std::optional<Reply> starved = try_send(server.port(), {http::verb::get, target});
  setrlimit(RLIMIT_AS, &unlimited);
  ASSERT_TRUE(starved) << "no answer when out of memory";
  expect_error(*starved, 503);
  EXPECT_EQ(starved->header("retry-after"), "1");

  ASSERT_TRUE(limited_to(800u << 20));
  const Counted full = get_counted(server.port(), target);
  setrlimit(RLIMIT_AS, &unlimited);
  EXPECT_EQ(full.status, 200) << full.head;
  EXPECT_GT(full.content_length, 16u << 20) << rows << " rows: more than the 16 MB spare above";
  EXPECT_EQ(full.body_bytes, full.content_length);
  EXPECT_EQ(api.get("/api/health").status, 200);
}

// =============================================================================================
// Unauthenticated clients cannot lock the token holder (or anyone) out.

TEST(ServerLimits, PublicStreamsCannotLockOutTheTokenHolder) {
  const std::string token = "the-token";
  constexpr std::size_t kPublic = 12;
  TestServer server(scratch("streams") / "data", token, 2, [&](ServerOptions& o) {
    o.max_connections = 24;
    o.max_public_streams = kPublic;
    o.max_public_streams_per_address = 100;  // the total cap is under test here
  });
  const Api api{server.port(), token};
  const std::string id = api.create({{"scene", tiny_scene()}});
  const std::string stream = "/api/runs/" + id + "/stream";

  std::vector<std::unique_ptr<WsClient>> clients;
  for (int k = 0; k < 40; ++k) {
    try {
      clients.push_back(std::make_unique<WsClient>(server.port(), stream));
    } catch (const std::exception&) {
      break;
    }
  }
  EXPECT_EQ(clients.size(), kPublic);
  const std::string refused = raw_upgrade(
      server.port(), stream, "Host: x\r\n" + kGoodKey + "Sec-WebSocket-Version: 13\r\n");
  EXPECT_EQ(status_of(refused), 503) << refused;
  const json error = json::parse(body_of(refused), nullptr, false);
  ASSERT_FALSE(error.is_discarded()) << refused;
  EXPECT_NE(error["error"]["message"].get<std::string>().find(std::to_string(kPublic)),
            std::string::npos);

  // The token holder's calls and streams still get in; so does everyone's health check.
  const std::optional<Reply> pause =
      try_send(server.port(), api.with_token({http::verb::post, "/api/runs/" + id + "/pause"}));
  ASSERT_TRUE(pause) << "pause was refused";
  EXPECT_EQ(pause->status, 200) << pause->body;
  const std::optional<Reply> health = try_send(server.port(), {http::verb::get, "/api/health"});
  ASSERT_TRUE(health) << "health was refused";
  EXPECT_EQ(health->status, 200);
  WsClient holder(server.port(), stream + "?token=" + token);
  EXPECT_EQ(holder.read().text()["type"], "hello");
  EXPECT_EQ(api.run(id)["stream"]["clients"], kPublic + 1);
  const std::optional<Reply> stop =
      try_send(server.port(), api.with_token({http::verb::post, "/api/runs/" + id + "/stop"}));
  ASSERT_TRUE(stop) << "stop was refused";
  EXPECT_EQ(stop->status, 200) << stop->body;

  // A closed stream frees its place.
  clients.pop_back();
  EXPECT_TRUE(wait_until(
      [&] {
        try {
          clients.push_back(std::make_unique<WsClient>(server.port(), stream));
          return true;
        } catch (const std::exception&) {
          return false;
        }
      },
      10s));
}

TEST(ServerLimits, PublicStreamsPerAddressAndWithoutAToken) {
  constexpr std::size_t kPerAddress = 5;
  TestServer server(scratch("streams-address") / "data", "", 2, [&](ServerOptions& o) {
    o.max_connections = 64;
    o.max_public_streams = 32;
    o.max_public_streams_per_address = kPerAddress;
  });
  const Api api{server.port()};
  const std::string id = api.create({{"scene", tiny_scene()}});
  const std::string stream = "/api/runs/" + id + "/stream";
  // No token configured: every stream is public, so the caps hold for all of them.
  std::vector<std::unique_ptr<WsClient>> clients;
  for (std::size_t k = 0; k < kPerAddress; ++k)
    clients.push_back(std::make_unique<WsClient>(server.port(), stream));
  const std::string refused = raw_upgrade(
      server.port(), stream, "Host: x\r\n" + kGoodKey + "Sec-WebSocket-Version: 13\r\n");
  EXPECT_EQ(status_of(refused), 503) << refused;
  EXPECT_NE(refused.find("127.0.0.1"), std::string::npos) << refused;
  EXPECT_EQ(api.post("/api/runs/" + id + "/pause").status, 200);
  // Options that leave no reserve are refused at start.
  sphles::control::ManagerOptions m;
  m.data_directory = scratch("streams-options") / "data";
  sphles::control::RunManager manager(m);
  ServerOptions o;
  o.port = 0;
  o.max_connections = 8;
  o.max_public_streams = 8;
  HttpServer bad(manager, o);
  EXPECT_THROW(bad.start(), std::invalid_argument);
}

/// Sockets that each send a request a byte at a time, or nothing at all, from one thread.
class Slowloris {
 public:
  Slowloris(unsigned short port, int sockets, std::chrono::milliseconds every)
      : thread_([this, port, sockets, every] { run(port, sockets, every); }) {}
  ~Slowloris() {
    stop_ = true;
    thread_.join();
  }
  bool wait_opened() {
    return wait_until([&] { return opened_.load(); }, 60s);
  }
  int closed_by_server() const { return closed_.load(); }

 private:
  /// A request line, then header lines without end.
  static char byte_at(std::size_t k) {
    static const std::string kLine = "GET /api/health HTTP/1.1\r\n", kHeader = "X-Slow: 1\r\n";
    return k < kLine.size() ? kLine[k] : kHeader[(k - kLine.size()) % kHeader.size()];
  }

  void run(unsigned short port, int count, std::chrono::milliseconds every) {
    net::io_context ioc;
    std::vector<std::unique_ptr<tcp::socket>> sockets;
    std::vector<std::size_t> sent;
    for (int k = 0; k < count && !stop_; ++k) {
      auto s = std::make_unique<tcp::socket>(ioc);
      beast::error_code ec;
      s->connect({net::ip::make_address("127.0.0.1"), port}, ec);
      if (ec) continue;
      s->non_blocking(true, ec);
      sockets.push_back(std::move(s));
      sent.push_back(0);
    }
    opened_ = true;
    while (!stop_) {
      for (std::size_t k = 0; k < sockets.size(); ++k) {
        if (!sockets[k]) continue;
        beast::error_code ec;
        const char byte = byte_at(sent[k]);
        net::write(*sockets[k], net::buffer(&byte, 1), ec);
        std::array<char, 256> buffer{};
        const std::size_t n = sockets[k]->read_some(net::buffer(buffer), ec);
        if ((ec && ec != net::error::would_block) || (n == 0 && !ec)) {
          ++closed_;
          sockets[k].reset();
          continue;
        }
        ++sent[k];
      }
      std::this_thread::sleep_for(every);
    }
  }

  std::atomic<bool> stop_{false}, opened_{false};
  std::atomic<int> closed_{0};
  std::thread thread_;
};

TEST(ServerLimits, SlowlorisSocketsCannotStarveRequests) {
  constexpr std::size_t kMax = 32;
  TestServer server(scratch("slowloris") / "data", "", 2, [&](ServerOptions& o) {
    o.max_connections = kMax;
    o.max_connections_per_address = 24;
    o.max_public_streams = 8;
    o.header_timeout = std::chrono::seconds(120);  // eviction under test, not the deadline
  });
  const Api api{server.port()};
  const std::string id = api.create({{"scene", tiny_scene()}});
  Slowloris attack(server.port(), 300, 100ms);
  ASSERT_TRUE(attack.wait_opened());
  for (int k = 0; k < 20; ++k) {
    const auto started = std::chrono::steady_clock::now();
    const std::optional<Reply> r = try_send(server.port(), {http::verb::get, "/api/health"});
    ASSERT_TRUE(r) << "request " << k << " was refused";
    EXPECT_EQ(r->status, 200);
    EXPECT_LT(std::chrono::steady_clock::now() - started, 10s);  // a hang detector, generous
  }
  EXPECT_EQ(api.post("/api/runs/" + id + "/pause").status, 200);
  // Evicted to make room: all but the 24 an address may hold.
  EXPECT_TRUE(wait_until([&] { return attack.closed_by_server() >= 300 - 24; }, 10s))
      << attack.closed_by_server();
  std::printf("open connections during the attack: %zu (max_connections %zu)\n",
              server.http->connections(), kMax);
}

TEST(ServerLimits, AHeaderMustArriveWithinItsDeadline) {
  TestServer server(scratch("header-deadline") / "data", "", 2, [](ServerOptions& o) {
    o.header_timeout = std::chrono::seconds(1);
    o.request_timeout = std::chrono::seconds(60);
  });
  Slowloris one(server.port(), 1, 200ms);
  ASSERT_TRUE(one.wait_opened());
  // Closed by the server after about a second, although it keeps sending.
  EXPECT_TRUE(wait_until([&] { return one.closed_by_server() == 1; }, 10s));
  EXPECT_EQ(Api{server.port()}.get("/api/health").status, 200);
}

// =============================================================================================
// Histories longer than one answer are paged or decimated, never an empty 200.

TEST(ServerLimits, LongTimeSeriesArePagedAndDecimatedNeverEmpty) {
  constexpr std::uint64_t kRows = 30000;
  TestServer server(scratch("history") / "data", "", 2, [](ServerOptions& o) {
    o.responses.max_rows = 5000;
    o.responses.max_bytes = 128u << 10;  // 1000 rows fit, 5000 do not
  });
  const Api api{server.port()};
  const std::string id = api.create({{"scene", tiny_scene()}, {"start", false}});
  write_timeseries(server.data_directory / "runs" / id / "timeseries.csv", kRows);
  const std::string base = "/api/runs/" + id + "/timeseries";

  // The whole series does not fit one answer: an error naming the way out, not an empty 200.
  Reply r = api.get(base);
  expect_error(r, 507, "limit");
  EXPECT_NE(r.body.find("5000"), std::string::npos) << r.body;
  // A page that would pass the byte limit: the same.
  expect_error(api.get(base + "?limit=5000"), 507);
  expect_error(api.get(base + "?limit=0"), 400, "limit");
  expect_error(api.get(base + "?limit=5001"), 400, "limit");
  expect_error(api.get(base + "?max_points=1"), 400, "max_points");
  expect_error(api.get(base + "?limit=10&max_points=10"), 400, "max_points");

  // Every row, once and in order, page by page.
  std::vector<std::uint64_t> steps;
  std::vector<double> energies;
  std::string next = base + "?limit=1000";
  int pages = 0;
  while (true) {
    r = api.get(next);
    ASSERT_EQ(r.status, 200) << r.body.substr(0, 300);
    const json page = r.body_json();
    ASSERT_EQ(page["data"].size(), 7u) << r.body.substr(0, 300);
    ASSERT_EQ(page["columns"][1], "step");
    for (const json& s : page["data"][1]) steps.push_back(s.get<std::uint64_t>());
    for (const json& e : page["data"][3]) energies.push_back(e.get<double>());
    ++pages;
    if (!page["more"].get<bool>()) break;
    ASSERT_LT(pages, 100);
    next = base +
           "?limit=1000&since_step=" + std::to_string(page["next_since_step"].get<std::uint64_t>());
  }
  EXPECT_EQ(pages, 30);
  ASSERT_EQ(steps.size(), kRows);
  for (std::uint64_t k = 0; k < kRows; ++k) {
    ASSERT_EQ(steps[k], k);
    ASSERT_DOUBLE_EQ(energies[k], 0.25 - static_cast<double>(k) * 1e-9);
  }

  // Decimated for a plot: at most max_points rows, the first and the last among them.
  const json plot = api.get(base + "?max_points=100").body_json();
  ASSERT_EQ(plot["data"].size(), 7u) << plot;
  const json& s = plot["data"][1];
  EXPECT_LE(s.size(), 100u);
  EXPECT_GE(s.size(), 50u);
  EXPECT_EQ(s.front(), 0);
  EXPECT_EQ(s.back(), kRows - 1);
  EXPECT_FALSE(plot["more"].get<bool>());
  EXPECT_GT(plot["stride"].get<std::uint64_t>(), 1u);
  // The tail since a step, as the dashboard appends it.
  const json tail = api.get(base + "?since_step=29990").body_json();
  ASSERT_EQ(tail["data"].size(), 7u) << tail;
  EXPECT_EQ(tail["data"][1].size(), 9u);
  EXPECT_FALSE(tail["more"].get<bool>());
  EXPECT_EQ(tail["next_since_step"], kRows - 1);
}

TEST(ServerLimits, TimeSeriesPast64MiBIsServedWhole) {
  TestServer server(scratch("history-large") / "data");
  const Api api{server.port()};
  const std::string id = api.create({{"scene", tiny_scene()}, {"start", false}});
  // Rows until the file passes 64 MiB (the old cap, past which the answer was an empty 200).
  const fs::path file = server.data_directory / "runs" / id / "timeseries.csv";
  const std::uint64_t rows = write_timeseries(file, 0, 64u << 20);
  const Reply r = api.get("/api/runs/" + id + "/timeseries");
  ASSERT_EQ(r.status, 200) << r.body.substr(0, 300);
  const json series = r.body_json();
  ASSERT_EQ(series["data"].size(), 7u) << r.body.substr(0, 300);
  ASSERT_EQ(series["data"][1].size(), rows);
  EXPECT_EQ(series["data"][1].front(), 0);
  EXPECT_EQ(series["data"][1].back(), rows - 1);
  EXPECT_FALSE(series["more"].get<bool>());
  const json tail =
      api.get("/api/runs/" + id + "/timeseries?since_step=" + std::to_string(rows - 3)).body_json();
  ASSERT_EQ(tail["data"].size(), 7u) << tail;
  EXPECT_EQ(tail["data"][1].size(), 2u);
}

// Sixteen clients without a token on one address fetching a 60 MiB time series again and again
// made the health check, the run list and a run's detail take 10-12 s: they queued behind the
// large reads. Large reads have threads of their own and a bound per address (429 beyond).
TEST(ServerLimits, LargeReadsOfOneAddressCannotStarveTheOthers) {
  TestServer server(scratch("bulk-reads") / "data");
  const Api api{server.port()};
  const std::string id = api.create({{"scene", tiny_scene()}, {"start", false}});
  write_timeseries(server.data_directory / "runs" / id / "timeseries.csv", 0, 60u << 20);
  std::atomic<bool> done{false};
  std::atomic<int> answered{0}, refused{0}, other{0};
  std::vector<std::thread> readers;
  for (int k = 0; k < 16; ++k)
    readers.emplace_back([&] {
      while (!done) {
        const Counted c = get_counted(server.port(), "/api/runs/" + id + "/timeseries");
        if (c.status == 200)
          ++answered;
        else if (c.status == 429 && c.head.find("Retry-After: 1") != std::string::npos)
          ++refused;
        else
          ++other;
      }
    });
  std::this_thread::sleep_for(500ms);
  double slowest = 0.0;
  for (int round = 0; round < 10; ++round)
    for (const std::string& target :
         std::vector<std::string>{"/api/health", "/api/runs", "/api/runs/" + id}) {
      const auto start = std::chrono::steady_clock::now();
      const Reply r = api.get(target);
      slowest = std::max(
          slowest, std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
      EXPECT_EQ(r.status, 200) << target;
    }
  // The large reads go on, two at a time, until one has been answered.
  ASSERT_TRUE(wait_until([&] { return answered > 0; }, 60s));
  done = true;
  for (std::thread& t : readers) t.join();
  EXPECT_LT(slowest, 0.5) << "seconds of the slowest small read (3.0 s before)";
  EXPECT_GT(refused.load(), 0);
  EXPECT_EQ(other.load(), 0);
}

TEST(ServerLimits, LongFramesIndexIsPagedBetweenSteps) {
  constexpr int kSteps = 4000;
  const std::vector<std::string> fields = {"omega2", "tau_sfs", "combined"};
  TestServer server(scratch("frames-index") / "data", "", 2,
                    [](ServerOptions& o) { o.responses.max_rows = 5000; });
  const Api api{server.port()};
  const std::string id = api.create({{"scene", tiny_scene()}, {"start", false}});
  const fs::path frames = server.data_directory / "runs" / id / "frames";
  fs::create_directories(frames);
  {
    std::ofstream out(frames / "index.csv");
    out << "time,step,field,file\n";
    for (int step = 0; step < kSteps; ++step)
      for (const std::string& f : fields)
        out << step * 0.01 << "," << step << "," << f << "," << f << "_" << step << ".png\n";
  }
  const std::string base = "/api/runs/" + id + "/frames";
  expect_error(api.get(base), 507, "limit");
  std::map<std::pair<std::uint64_t, std::string>, int> seen;
  std::string next = base + "?limit=1000";
  for (int page = 0;; ++page) {
    ASSERT_LT(page, 100);
    const Reply r = api.get(next);
    ASSERT_EQ(r.status, 200) << r.body.substr(0, 300);
    const json rows = r.body_json();
    ASSERT_TRUE(rows.is_array());
    EXPECT_EQ(rows.size() % fields.size(), 0u) << "a page split a step";
    for (const json& row : rows) {
      ++seen[{row["step"].get<std::uint64_t>(), row["field"].get<std::string>()}];
      EXPECT_EQ(row["url"], base + "/" + row["file"].get<std::string>());
    }
    if (r.header("x-sphles-more") == "false") break;
    ASSERT_EQ(r.header("x-sphles-more"), "true");
    next = base + "?limit=1000&since_step=" + r.header("x-sphles-next-since-step");
  }
  EXPECT_EQ(seen.size(), kSteps * fields.size());
  for (const auto& [key, count] : seen) EXPECT_EQ(count, 1) << key.first << " " << key.second;
}

// =============================================================================================
// Malformed WebSocket handshakes get the documented JSON error.

TEST(ServerLimits, MalformedWebSocketUpgradesAnswerJsonErrors) {
  TestServer server(scratch("handshake") / "data");
  const Api api{server.port()};
  const std::string id = api.create({{"scene", tiny_scene()}, {"start", false}});
  const std::string stream = "/api/runs/" + id + "/stream";
  const std::string host = "Host: x\r\n", v13 = "Sec-WebSocket-Version: 13\r\n";
  expect_raw_error(raw_upgrade(server.port(), stream, host + v13), 400, "Sec-WebSocket-Key");
  expect_raw_error(raw_upgrade(server.port(), stream, host + "Sec-WebSocket-Key: abc\r\n" + v13),
                   400, "Sec-WebSocket-Key");
  expect_raw_error(raw_upgrade(server.port(), stream, host + kGoodKey), 400,
                   "Sec-WebSocket-Version");
  const std::string v8 =
      raw_upgrade(server.port(), stream, host + kGoodKey + "Sec-WebSocket-Version: 8\r\n");
  expect_raw_error(v8, 426, "Sec-WebSocket-Version");
  EXPECT_NE(v8.find("Sec-WebSocket-Version: 13\r\n"), std::string::npos) << v8;
  expect_raw_error(raw_upgrade(server.port(), stream, kGoodKey + v13), 400, "Host");
  expect_raw_error(raw_upgrade(server.port(), "/api/runs/0999-none/stream", host + kGoodKey + v13),
                   404, "id");
  EXPECT_EQ(status_of(raw_upgrade(server.port(), stream, host + kGoodKey + v13)), 101);
  EXPECT_EQ(api.get("/api/health").status, 200);
}

}  // namespace
