// TLS for HTTPS and WSS (issue 22): the certificate and private key of --tls-cert / --tls-key,
// read and checked by us before libwebsockets sees them, and installed into the listening
// vhost's OpenSSL SSL_CTX, at start and again on SIGHUP.
//
// Why we read the files instead of leaving it to lws: lws 4.1.6 reports a bad file as "cannot
// create context" without naming it, and it has no call that reloads a vhost's certificate.
// OpenSSL copies the context's certificate into each connection when the connection is created
// (SSL_new), so replacing the context's certificate changes what new handshakes see and leaves
// connections already open (and their sessions) alone.
#pragma once

#include <memory>
#include <string>

struct ssl_ctx_st;  // OpenSSL's SSL_CTX

namespace catgs::server {

// A certificate chain and the private key that matches its first certificate. Immutable once
// loaded; copies share the OpenSSL objects.
class TlsCredentials {
 public:
  // Reads `cert_path` (PEM: the server certificate first, then any intermediates) and
  // `key_path` (PEM private key, unencrypted: a server has nobody to type a passphrase).
  // Throws std::runtime_error naming the option and the file when a file cannot be read, holds
  // no certificate / no key, or the key does not belong to the certificate.
  static TlsCredentials load(const std::string& cert_path, const std::string& key_path);

  // Makes `ctx` present these credentials from its next handshake on (replacing what it had),
  // and accept TLS 1.2 or later only. Throws std::runtime_error when OpenSSL refuses them.
  void install(ssl_ctx_st* ctx) const;

  // The server certificate in one line for the log: subject, serial (hex) and end of validity,
  // e.g. "/CN=stream.example, serial 1A2B, valid until Nov 23 11:55:00 2026 GMT", so an operator
  // sees which certificate a reload put in place and when it runs out.
  std::string describe() const;

 private:
  struct Material;
  std::shared_ptr<const Material> material_;
};

}  // namespace catgs::server
