#include "export/local_server.h"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <fstream>
#include <sstream>

#include "calib/error.h"

namespace omni {
namespace {

namespace fs = std::filesystem;

std::string ContentType(const fs::path& path) {
  const std::string ext = path.extension().string();
  if (ext == ".html") return "text/html; charset=utf-8";
  if (ext == ".js") return "text/javascript; charset=utf-8";
  if (ext == ".css") return "text/css; charset=utf-8";
  if (ext == ".json") return "application/json";
  if (ext == ".png") return "image/png";
  if (ext == ".glb") return "model/gltf-binary";
  return "application/octet-stream";
}

void SendAll(int connection, const std::string& bytes) {
  size_t sent = 0;
  while (sent < bytes.size()) {
    const ssize_t n = send(connection, bytes.data() + sent, bytes.size() - sent, MSG_NOSIGNAL);
    if (n <= 0) return;  // the browser went away
    sent += static_cast<size_t>(n);
  }
}

std::string PercentDecoded(const std::string& text) {
  std::string out;
  for (size_t i = 0; i < text.size(); ++i) {
    if (text[i] == '%' && i + 2 < text.size() && std::isxdigit(text[i + 1]) &&
        std::isxdigit(text[i + 2])) {
      out.push_back(static_cast<char>(std::stoi(text.substr(i + 1, 2), nullptr, 16)));
      i += 2;
    } else {
      out.push_back(text[i]);
    }
  }
  return out;
}

}  // namespace

std::string LocalServerOptions::Check() const {
  in_addr parsed{};
  if (inet_pton(AF_INET, address.c_str(), &parsed) != 1 || (ntohl(parsed.s_addr) >> 24) != 127)
    return "address: must be a loopback address 127.x.y.z";
  if (port < 0 || port > 65535) return "port: must be in [0, 65535]";
  return {};
}

LocalServer::LocalServer(const fs::path& root, const LocalServerOptions& options)
    : root_(fs::weakly_canonical(root)), address_(options.address) {
  ThrowIfInvalid(options.Check(), "LocalServerOptions");
  socket_ = socket(AF_INET, SOCK_STREAM, 0);
  if (socket_ < 0) throw InputError("", "--port", std::string("no socket: ") + strerror(errno));
  const int yes = 1;
  setsockopt(socket_, SOL_SOCKET, SO_REUSEADDR, &yes, sizeof(yes));
  sockaddr_in where{};
  where.sin_family = AF_INET;
  where.sin_port = htons(static_cast<uint16_t>(options.port));
  inet_pton(AF_INET, options.address.c_str(), &where.sin_addr);
  if (bind(socket_, reinterpret_cast<sockaddr*>(&where), sizeof(where)) != 0 ||
      listen(socket_, 16) != 0) {
    const std::string reason = strerror(errno);
    close(socket_);
    throw InputError("", "--port",
                     options.address + ":" + std::to_string(options.port) + ": " + reason);
  }
  socklen_t length = sizeof(where);
  getsockname(socket_, reinterpret_cast<sockaddr*>(&where), &length);
  port_ = ntohs(where.sin_port);
}

LocalServer::~LocalServer() {
  if (socket_ >= 0) close(socket_);
}

std::string LocalServer::Url() const {
  return "http://" + address_ + ":" + std::to_string(port_) + "/index.html";
}

void LocalServer::Serve(long max_requests) {
  for (long answered = 0; max_requests <= 0 || answered < max_requests; ++answered) {
    const int connection = accept(socket_, nullptr, nullptr);
    if (connection < 0) {
      if (errno == EINTR) continue;
      throw InputError("", "--port", std::string("accept: ") + strerror(errno));
    }
    Answer(connection);
    close(connection);
  }
}

void LocalServer::Answer(int connection) const {
  std::string request;
  char buffer[4096];
  while (request.find("\r\n\r\n") == std::string::npos && request.size() < 65536) {
    const ssize_t n = recv(connection, buffer, sizeof(buffer), 0);
    if (n <= 0) return;
    request.append(buffer, static_cast<size_t>(n));
  }
  std::istringstream line(request.substr(0, request.find("\r\n")));
  std::string method, target;
  line >> method >> target;
  auto reply = [&](const std::string& status, const std::string& type, const std::string& body,
                   bool head) {
    std::ostringstream header;
    header << "HTTP/1.0 " << status << "\r\nContent-Type: " << type
           << "\r\nContent-Length: " << body.size()
           << "\r\nCache-Control: no-store\r\nConnection: close\r\n\r\n";
    SendAll(connection, header.str() + (head ? std::string() : body));
  };
  if (method != "GET" && method != "HEAD") {
    reply("405 Method Not Allowed", "text/plain", "GET or HEAD only\n", false);
    return;
  }
  const bool head = method == "HEAD";
  std::string path = PercentDecoded(target.substr(0, target.find_first_of("?#")));
  if (path.empty() || path == "/") path = "/index.html";
  const fs::path relative = fs::path(path.substr(1)).lexically_normal();
  const std::string relative_text = relative.string();
  const bool escapes = path[0] != '/' || relative.is_absolute() || relative_text.empty() ||
                       relative_text.rfind("..", 0) == 0;
  const fs::path file = root_ / relative;
  if (escapes || !fs::is_regular_file(file)) {
    reply("404 Not Found", "text/plain", "not found\n", head);
    return;
  }
  std::ifstream in(file, std::ios::binary);
  std::ostringstream body;
  body << in.rdbuf();
  reply("200 OK", ContentType(file), body.str(), head);
}

}  // namespace omni
