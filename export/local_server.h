#pragma once
// A small HTTP/1.0 file server for `omnisculpt view OUT --serve`: GET and HEAD of the files
// under one folder, on a loopback address only, one connection at a time (a viewer for one
// person). Paths with ".." or outside the folder get 404.

#include <filesystem>
#include <string>

namespace omni {

struct LocalServerOptions {
  std::string address = "127.0.0.1";  // loopback only: 127.0.0.0/8
  int port = 8080;                    // 0: any free port (LocalServer::port() tells which)

  std::string Check() const;
};

class LocalServer {
 public:
  // Binds and listens; throws InputError("--port", ...) when the port cannot be had.
  LocalServer(const std::filesystem::path& root, const LocalServerOptions& options);
  ~LocalServer();
  LocalServer(const LocalServer&) = delete;
  LocalServer& operator=(const LocalServer&) = delete;

  int port() const { return port_; }
  std::string Url() const;  // http://127.0.0.1:<port>/index.html
  // Answers requests until the process is stopped (or `max_requests` were answered, when > 0).
  void Serve(long max_requests = 0);

 private:
  void Answer(int connection) const;

  std::filesystem::path root_;
  std::string address_;
  int socket_ = -1;
  int port_ = 0;
};

}  // namespace omni
