// SPDX-License-Identifier: GPL-3.0-or-later
// The REST router without sockets: a Router over a real control::RunManager on a scratch data
// directory, given in-memory requests. Documents the order of checks of server/router.hpp and
// docs/api.md ("Conventions": path 404, method 405, token 401, empty body 400, Content-Type 415,
// body 400, run id 404) and what HEAD, malformed targets and static paths get, as the server
// answers them today. test_server.cpp covers the same API through real connections.
#include "server/websocket_session.hpp"
#include "server_test_support.hpp"

namespace {

using sphles::server::Response;
using sphles::server::Router;
using sphles_server_test::expect_error;
using sphles_server_test::json;
using sphles_server_test::Reply;
using sphles_server_test::scratch;
using sphles_server_test::tiny_scene;
namespace http = boost::beast::http;
namespace fs = std::filesystem;

constexpr const char* kToken = "router-test-token";

/// A router with its own run manager, data directory and web root, as HttpServer builds one.
class RouterTest : public ::testing::Test {
 protected:
  void SetUp() override { start(""); }
  void TearDown() override { stop(); }

  /// (Re)builds the router; `token` non-empty: mutating routes need it.
  void start(const std::string& token) {
    stop();
    const fs::path base = scratch("router");
    sphles::control::ManagerOptions m;
    m.data_directory = base / "data";
    m.run_options.threads = 1;
    manager_ = std::make_unique<sphles::control::RunManager>(m);
    streams_ = std::make_unique<sphles::server::StreamRegistry>();
    products_ = std::make_unique<sphles::server::ProductCache>(1u << 20);
    sphles::server::RouterOptions options;
    options.token = token;
    options.web_root = sphles_server_test::make_web_root(base / "site");
    options.reference_dir = fs::path(SPHLES_SOURCE_DIR) / "data" / "reference";
    router_ = std::make_unique<Router>(*manager_, *streams_, *products_, options);
  }

  void stop() {
    router_.reset();
    if (manager_) manager_->shutdown();
    products_.reset();
    streams_.reset();
    manager_.reset();
  }

  /// The router's answer to one request; a Content-Type and a bearer token when given.
  Response handle(http::verb method, const std::string& target, const std::string& body = "",
                  const std::string& content_type = "", const std::string& token = "") const {
    sphles::server::Request request{method, target, 11};
    request.set(http::field::host, "127.0.0.1");
    if (!content_type.empty()) request.set(http::field::content_type, content_type);
    if (!token.empty()) request.set(http::field::authorization, "Bearer " + token);
    request.body() = body;
    request.prepare_payload();
    return router_->handle(request);
  }

  /// The answer as the socket tests see one, for expect_error.
  static Reply reply(const Response& res) {
    return sphles_server_test::reply_of(res, std::string(res.body().view()));
  }

  Reply get(const std::string& target) const { return reply(handle(http::verb::get, target)); }

  std::unique_ptr<sphles::control::RunManager> manager_;
  std::unique_ptr<sphles::server::StreamRegistry> streams_;
  std::unique_ptr<sphles::server::ProductCache> products_;
  std::unique_ptr<Router> router_;
};

TEST_F(RouterTest, HealthAndAnEmptyRunList) {
  const Reply health = get("/api/health");
  ASSERT_EQ(health.status, 200) << health.body;
  EXPECT_EQ(health.header("content-type"), "application/json");
  EXPECT_EQ(health.header("cache-control"), "no-store");
  EXPECT_EQ(health.body_json(), json({{"status", "ok"}, {"version", SPHLES_VERSION}, {"runs", 0}}));

  const Reply runs = get("/api/runs");
  ASSERT_EQ(runs.status, 200) << runs.body;
  EXPECT_EQ(runs.body_json(), json::array());
}

TEST_F(RouterTest, UnknownApiPathIs404) {
  expect_error(get("/api/nothing-here"), 404, "path");
  // The path is checked before the method.
  expect_error(reply(handle(http::verb::delete_, "/api/nothing-here")), 404, "path");
}

TEST_F(RouterTest, WrongMethodIs405WithAllow) {
  const Reply r = reply(handle(http::verb::delete_, "/api/runs"));
  expect_error(r, 405, "method");
  EXPECT_EQ(r.header("allow"), "GET, HEAD, POST");
  const Reply one = reply(handle(http::verb::put, "/api/runs/some-run"));
  expect_error(one, 405, "method");
  EXPECT_EQ(one.header("allow"), "GET, HEAD, DELETE");
}

TEST_F(RouterTest, MutatingRoutesNeedTheToken) {
  start(kToken);
  const std::string create = json{{"scene", tiny_scene()}, {"start", false}}.dump();
  for (const std::string token : {"", "not-the-token"}) {
    const Reply r = reply(handle(http::verb::post, "/api/runs", create, "application/json", token));
    expect_error(r, 401, "Authorization");
    EXPECT_EQ(r.header("www-authenticate"), "Bearer");
  }
  // The method is checked before the token, the token before the Content-Type.
  expect_error(reply(handle(http::verb::put, "/api/runs", create, "application/json")), 405,
               "method");
  expect_error(reply(handle(http::verb::post, "/api/runs", "preset=tgv2d", "text/plain")), 401,
               "Authorization");
  // Reading needs no token.
  EXPECT_EQ(get("/api/runs").status, 200);
  // Nothing was created.
  EXPECT_TRUE(manager_->list().empty());
}

TEST_F(RouterTest, JsonRoutesCheckContentTypeThenBody) {
  start(kToken);
  const auto post = [&](const std::string& body, const std::string& type = "application/json") {
    return reply(handle(http::verb::post, "/api/runs", body, type, kToken));
  };
  expect_error(post("preset=tgv2d", "text/plain"), 415, "Content-Type");
  // An empty body is a 400 before its Content-Type is looked at.
  const Reply empty = post("", "text/plain");
  expect_error(empty, 400);
  EXPECT_TRUE(empty.body_json()["error"]["field"].is_null());
  expect_error(post("{\"scene\": "), 400);
  expect_error(post("[1,2]"), 400);
  expect_error(post(json{{"scene", tiny_scene()}, {"colour", "red"}}.dump()), 400, "colour");
  json bad_scene = tiny_scene();
  bad_scene["kernel"]["shape"] = "round";
  expect_error(post(json{{"scene", bad_scene}}.dump()), 400, "kernel.shape");
  // A structured +json media type is JSON too (RFC 6839 §3.1).
  expect_error(post(json{{"preset", 5}}.dump(), "application/merge-patch+json"), 400, "preset");
  EXPECT_TRUE(manager_->list().empty());
}

TEST_F(RouterTest, UnknownRunIs404) {
  expect_error(get("/api/runs/no-such-run"), 404, "id");
  expect_error(get("/api/runs/no-such-run/timeseries"), 404, "id");
  expect_error(reply(handle(http::verb::post, "/api/runs/no-such-run/start")), 404, "id");
  // A parameter change's Content-Type and body are checked before its run.
  const auto patch = [&](const std::string& body, const std::string& type) {
    return reply(handle(http::verb::patch, "/api/runs/no-such-run/parameters", body, type));
  };
  expect_error(patch("time.end=3", "text/plain"), 415, "Content-Type");
  expect_error(patch("{\"time\": ", "application/json"), 400);
  expect_error(patch(json{{"time", {{"end", 3.0}}}}.dump(), "application/json"), 404, "id");
}

TEST_F(RouterTest, HeadHasTheGetsLengthAndNoBody) {
  const Response got = handle(http::verb::get, "/api/health");
  ASSERT_EQ(got.result_int(), 200u);
  ASSERT_FALSE(got.body().empty());
  const Response head = handle(http::verb::head, "/api/health");
  EXPECT_EQ(head.result_int(), 200u);
  EXPECT_TRUE(head.body().empty());
  EXPECT_EQ(head[http::field::content_length], std::to_string(got.body().size()));
  EXPECT_EQ(head[http::field::content_type], "application/json");
}

TEST_F(RouterTest, MalformedPercentEncodingIs400) {
  expect_error(get("/api/runs/%zz"), 400, "path");
  expect_error(get("/api/runs/%"), 400, "path");
  // An encoded '/' would change which route matches.
  expect_error(get("/api/runs%2fsome-run"), 400, "path");
  expect_error(get("/api/runs?since_step=%zz"), 400, "query");
  expect_error(get("runs"), 400, "target");
}

TEST_F(RouterTest, StaticFilesStayInsideTheWebRoot) {
  const Reply index = get("/");
  ASSERT_EQ(index.status, 200) << index.body;
  EXPECT_EQ(index.header("content-type"), "text/html; charset=utf-8");
  EXPECT_NE(index.body.find("sphles"), std::string::npos);

  for (const char* target : {"/../secret.txt", "/%2e%2e/secret.txt", "/sub/../../secret.txt"}) {
    const Reply r = get(target);
    expect_error(r, 400, "path");
    EXPECT_EQ(r.body.find(sphles_server_test::kSecret), std::string::npos) << target;
  }
  // A symbolic link out of the root, and a hidden file: as if they were not there.
  for (const char* target : {"/escape/secret.txt", "/.hidden"}) {
    const Reply r = get(target);
    expect_error(r, 404, "path");
    EXPECT_EQ(r.body.find(sphles_server_test::kSecret), std::string::npos) << target;
  }
  const Reply post = reply(handle(http::verb::post, "/index.html"));
  expect_error(post, 405, "method");
  EXPECT_EQ(post.header("allow"), "GET, HEAD");
}

TEST_F(RouterTest, CreateThenGetARun) {
  start(kToken);
  const std::string body =
      json{{"scene", tiny_scene()}, {"name", "first"}, {"start", false}}.dump();
  const Reply created =
      reply(handle(http::verb::post, "/api/runs", body, "application/json", kToken));
  ASSERT_EQ(created.status, 201) << created.body;
  const std::string id = created.body_json()["id"];
  ASSERT_FALSE(id.empty());
  EXPECT_EQ(created.header("location"), "/api/runs/" + id);
  EXPECT_EQ(created.body_json()["state"], "created");
  EXPECT_EQ(created.body_json()["name"], "first");

  const Reply detail = get("/api/runs/" + id);
  ASSERT_EQ(detail.status, 200) << detail.body;
  EXPECT_EQ(detail.body_json()["id"], id);
  EXPECT_EQ(detail.body_json()["state"], "created");
  EXPECT_EQ(detail.body_json()["scene"]["particles_per_side"], 16);
  EXPECT_EQ(detail.body_json()["available"]["resolved"], false);

  const Reply runs = get("/api/runs");
  ASSERT_EQ(runs.status, 200);
  ASSERT_EQ(runs.body_json().size(), 1u);
  EXPECT_EQ(runs.body_json()[0]["id"], id);
  EXPECT_EQ(get("/api/health").body_json()["runs"], 1);
}

}  // namespace

// The bulk threads take the large reads and the movies (their method and path), never a
// request the control pool or the read pool answers.
TEST_F(RouterTest, LargeReadsAndMoviesAreBulkRequests) {
  const auto bulk = [&](http::verb method, const std::string& target) {
    sphles::server::Request request{method, target, 11};
    return router_->is_bulk(request);
  };
  EXPECT_TRUE(bulk(http::verb::get, "/api/runs/0001-a/timeseries?max_points=10"));
  EXPECT_TRUE(bulk(http::verb::head, "/api/runs/0001-a/files/spectra/index.csv"));
  EXPECT_TRUE(bulk(http::verb::post, "/api/runs/0001-a/movies"));
  EXPECT_FALSE(bulk(http::verb::get, "/api/runs/0001-a/movies"));  // no such route: a 405
  EXPECT_FALSE(bulk(http::verb::post, "/api/runs/0001-a/stop"));
  EXPECT_FALSE(bulk(http::verb::get, "/api/runs/0001-a"));
}
