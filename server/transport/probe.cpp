#include "transport/probe.h"

#include <utility>  // Boost 1.74 Asio under C++20 needs std::exchange declared first

#include <boost/asio/connect.hpp>
#include <boost/asio/io_context.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <boost/asio/ssl/context.hpp>
#include <boost/beast/core/flat_buffer.hpp>
#include <boost/beast/core/tcp_stream.hpp>
#include <boost/beast/http/empty_body.hpp>
#include <boost/beast/http/read.hpp>
#include <boost/beast/http/string_body.hpp>
#include <boost/beast/http/write.hpp>
#include <boost/beast/ssl/ssl_stream.hpp>

#include <chrono>
#include <stdexcept>

namespace catgs::server {

namespace beast = boost::beast;
namespace http = boost::beast::http;
using tcp = boost::asio::ip::tcp;

namespace {

// One GET on a connected stream (plain or TLS); the status code.
template <class Stream>
int get_status(Stream& stream, const ProbeTarget& t) {
  http::request<http::empty_body> req{http::verb::get, t.target, 11};
  req.set(http::field::host, t.host);
  req.set(http::field::connection, "close");
  http::write(stream, req);
  beast::flat_buffer buffer;
  http::response_parser<http::string_body> parser;
  parser.body_limit(1 << 20);
  http::read(stream, buffer, parser);
  return static_cast<int>(parser.get().result_int());
}

}  // namespace

ProbeTarget parse_probe_url(const std::string& url) {
  auto bad = [&](const std::string& why) { return std::invalid_argument("--probe " + url + ": " + why); };
  ProbeTarget t;
  t.tls = url.rfind("https://", 0) == 0;
  const std::string scheme = t.tls ? "https://" : "http://";
  if (url.rfind(scheme, 0) != 0) throw bad("needs an http:// or https:// URL");
  if (t.tls) t.port = "443";
  std::string authority = url.substr(scheme.size());
  if (const auto slash = authority.find('/'); slash != std::string::npos) {
    t.target = authority.substr(slash);
    authority.resize(slash);
  }
  std::string port;
  if (!authority.empty() && authority[0] == '[') {  // [IPv6]:port
    const auto close = authority.find(']');
    if (close == std::string::npos) throw bad("unclosed [ in the host");
    t.host = authority.substr(1, close - 1);
    if (close + 1 < authority.size()) {
      if (authority[close + 1] != ':') throw bad("junk after ]");
      port = authority.substr(close + 2);
    }
  } else if (const auto colon = authority.rfind(':'); colon != std::string::npos) {
    t.host = authority.substr(0, colon);
    port = authority.substr(colon + 1);
  } else {
    t.host = authority;
  }
  if (t.host.empty()) throw bad("no host");
  if (!port.empty()) {
    if (port.size() > 5 || port.find_first_not_of("0123456789") != std::string::npos) throw bad("bad port");
    const int p = std::stoi(port);
    if (p < 1 || p > 65535) throw bad("port out of 1..65535");
    t.port = port;
  }
  return t;
}

int probe_http(const std::string& url, int timeout_ms, std::string* error) {
  const ProbeTarget t = parse_probe_url(url);
  boost::asio::io_context io;
  beast::tcp_stream stream(io);
  int status = -1;
  std::string why;
  try {
    // One deadline for the whole exchange: a hung server must not hang the health check.
    stream.expires_after(std::chrono::milliseconds(timeout_ms));
    tcp::resolver resolver(io);
    stream.connect(resolver.resolve(t.host, t.port));
    if (t.tls) {
      boost::asio::ssl::context ctx(boost::asio::ssl::context::tls_client);
      ctx.set_verify_mode(boost::asio::ssl::verify_none);  // probe.h: liveness, not identity
      beast::ssl_stream<beast::tcp_stream&> tls(stream, ctx);
      tls.handshake(boost::asio::ssl::stream_base::client);
      status = get_status(tls, t);
    } else {
      status = get_status(stream, t);
    }
  } catch (const std::exception& e) {
    why = e.what();
  }
  beast::error_code ignored;
  stream.socket().shutdown(tcp::socket::shutdown_both, ignored);
  if (error) *error = why;
  return status;
}

}  // namespace catgs::server
