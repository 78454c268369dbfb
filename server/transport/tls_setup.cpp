#include "transport/tls_setup.h"

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <stdexcept>
#include <vector>

#include <openssl/bn.h>
#include <openssl/err.h>
#include <openssl/evp.h>
#include <openssl/pem.h>
#include <openssl/ssl.h>
#include <openssl/x509.h>

namespace catgs::server {

namespace {

struct BioFree {
  void operator()(BIO* b) const { BIO_free(b); }
};
struct X509Free {
  void operator()(X509* x) const { X509_free(x); }
};
struct KeyFree {
  void operator()(EVP_PKEY* k) const { EVP_PKEY_free(k); }
};
struct ChainFree {
  void operator()(STACK_OF(X509) * s) const { sk_X509_pop_free(s, X509_free); }
};

// OpenSSL's reason for the last failure ("" when it left none), and the queue emptied so the
// next call starts clean.
std::string openssl_reason() {
  const unsigned long e = ERR_peek_last_error();
  ERR_clear_error();
  if (!e) return "";
  char buf[256];
  ERR_error_string_n(e, buf, sizeof(buf));
  return std::string(": ") + buf;
}

std::unique_ptr<BIO, BioFree> open_file(const char* option, const std::string& path) {
  errno = 0;
  std::unique_ptr<BIO, BioFree> bio(BIO_new_file(path.c_str(), "r"));
  if (!bio) {
    const std::string why = errno ? std::strerror(errno) : "cannot open";
    ERR_clear_error();
    throw std::runtime_error(std::string(option) + " " + path + ": " + why);
  }
  return bio;
}

// A key file with a passphrase must fail, not prompt on the terminal (OpenSSL's default).
int no_passphrase(char*, int, int, void*) { return 0; }

}  // namespace

struct TlsCredentials::Material {
  std::unique_ptr<X509, X509Free> cert;
  std::unique_ptr<STACK_OF(X509), ChainFree> chain;  // intermediates after the first certificate
  std::unique_ptr<EVP_PKEY, KeyFree> key;
};

TlsCredentials TlsCredentials::load(const std::string& cert_path, const std::string& key_path) {
  ERR_clear_error();
  auto m = std::make_shared<Material>();
  auto certs = open_file("--tls-cert", cert_path);
  m->cert.reset(PEM_read_bio_X509(certs.get(), nullptr, no_passphrase, nullptr));
  if (!m->cert) throw std::runtime_error("--tls-cert " + cert_path + ": no PEM certificate in it" + openssl_reason());
  m->chain.reset(sk_X509_new_null());
  while (X509* next = PEM_read_bio_X509(certs.get(), nullptr, no_passphrase, nullptr))
    sk_X509_push(m->chain.get(), next);
  ERR_clear_error();  // the end of the file reads as an error

  auto keys = open_file("--tls-key", key_path);
  m->key.reset(PEM_read_bio_PrivateKey(keys.get(), nullptr, no_passphrase, nullptr));
  if (!m->key)
    throw std::runtime_error("--tls-key " + key_path + ": no unencrypted PEM private key in it" + openssl_reason());
  if (X509_check_private_key(m->cert.get(), m->key.get()) != 1)
    throw std::runtime_error("--tls-key " + key_path + " does not belong to the certificate in --tls-cert " +
                             cert_path + openssl_reason());
  TlsCredentials c;
  c.material_ = std::move(m);
  return c;
}

void TlsCredentials::install(ssl_ctx_st* ctx) const {
  if (!material_) throw std::logic_error("TlsCredentials::install: nothing loaded");
  // TLS 1.2 at least whatever the system's OpenSSL configuration says (RFC 8996 retired 1.0/1.1).
  if (SSL_CTX_set_min_proto_version(ctx, TLS1_2_VERSION) != 1)
    throw std::runtime_error("OpenSSL refused TLS 1.2 as the lowest version" + openssl_reason());
  // override = 1: replace the certificate, key and chain the context had, in one call.
  if (SSL_CTX_use_cert_and_key(ctx, material_->cert.get(), material_->key.get(), material_->chain.get(), 1) != 1)
    throw std::runtime_error("OpenSSL refused the certificate and key" + openssl_reason());
}

std::string TlsCredentials::describe() const {
  if (!material_) return "";
  X509* cert = material_->cert.get();
  char subject[512];
  X509_NAME_oneline(X509_get_subject_name(cert), subject, sizeof(subject));
  std::string serial = "?";
  if (BIGNUM* bn = ASN1_INTEGER_to_BN(X509_get0_serialNumber(cert), nullptr)) {
    if (char* h = BN_bn2hex(bn)) {
      serial = h;
      OPENSSL_free(h);
    }
    BN_free(bn);
  }
  std::string until = "?";
  std::unique_ptr<BIO, BioFree> out(BIO_new(BIO_s_mem()));
  if (out && ASN1_TIME_print(out.get(), X509_get0_notAfter(cert)) == 1) {
    char* text = nullptr;
    const long n = BIO_get_mem_data(out.get(), &text);
    until.assign(text, static_cast<std::size_t>(n));
  }
  return std::string(subject) + ", serial " + serial + ", valid until " + until;
}

}  // namespace catgs::server
