#include "auth.hpp"

#include <openssl/crypto.h>
#include <openssl/evp.h>
#include <openssl/rand.h>

#include <array>
#include <charconv>

#include <fmt/format.h>

namespace cell::monitor {
namespace {

constexpr std::size_t kSaltBytes = 16;
constexpr std::size_t kHashBytes = 32;
constexpr std::size_t kTokenBytes = 32;
constexpr int kMaxFailures = 5;
constexpr auto kFailureWindow = std::chrono::seconds(60);
constexpr auto kLockout = std::chrono::seconds(60);

std::string base64(const unsigned char* data, std::size_t n) {
  std::string out(4 * ((n + 2) / 3) + 1, '\0');
  const int len = EVP_EncodeBlock(reinterpret_cast<unsigned char*>(out.data()), data,
                                  static_cast<int>(n));
  out.resize(static_cast<std::size_t>(len));
  return out;
}

std::optional<std::vector<unsigned char>> unbase64(const std::string& text) {
  if (text.empty() || text.size() % 4 != 0) {
    return std::nullopt;
  }
  std::vector<unsigned char> out(3 * text.size() / 4 + 1);
  const int len = EVP_DecodeBlock(out.data(), reinterpret_cast<const unsigned char*>(text.data()),
                                  static_cast<int>(text.size()));
  if (len < 0) {
    return std::nullopt;
  }
  std::size_t n = static_cast<std::size_t>(len);
  // EVP_DecodeBlock counts the padding's zero bytes: drop them.
  for (std::size_t i = text.size(); i > 0 && text[i - 1] == '='; --i) {
    --n;
  }
  out.resize(n);
  return out;
}

bool pbkdf2(const std::string& password, const unsigned char* salt, std::size_t salt_n,
            int iterations, unsigned char* out, std::size_t out_n) {
  return PKCS5_PBKDF2_HMAC(password.data(), static_cast<int>(password.size()), salt,
                           static_cast<int>(salt_n), iterations, EVP_sha256(),
                           static_cast<int>(out_n), out) == 1;
}

}  // namespace

Result<std::string> hash_password(const std::string& password, int iterations) {
  if (iterations < 1000) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("PBKDF2 iterations must be >= 1000, got {}", iterations)};
  }
  if (password.empty()) {
    return Error{Errc::kInvalidArgument, "the password is empty"};
  }
  std::array<unsigned char, kSaltBytes> salt{};
  std::array<unsigned char, kHashBytes> hash{};
  if (RAND_bytes(salt.data(), static_cast<int>(salt.size())) != 1 ||
      !pbkdf2(password, salt.data(), salt.size(), iterations, hash.data(), hash.size())) {
    return Error{Errc::kIo, "OpenSSL could not derive the key"};
  }
  return fmt::format("pbkdf2-sha256${}${}${}", iterations, base64(salt.data(), salt.size()),
                     base64(hash.data(), hash.size()));
}

bool verify_password(const std::string& password, const std::string& encoded) {
  // pbkdf2-sha256$<iter>$<salt>$<hash>
  const std::string prefix = "pbkdf2-sha256$";
  if (encoded.rfind(prefix, 0) != 0) {
    return false;
  }
  const std::size_t a = prefix.size();
  const std::size_t b = encoded.find('$', a);
  const std::size_t c = b == std::string::npos ? b : encoded.find('$', b + 1);
  if (c == std::string::npos || encoded.find('$', c + 1) != std::string::npos) {
    return false;
  }
  int iterations = 0;
  const auto [end, ec] = std::from_chars(encoded.data() + a, encoded.data() + b, iterations);
  if (ec != std::errc() || end != encoded.data() + b || iterations < 1000 ||
      iterations > 10'000'000) {
    return false;
  }
  const auto salt = unbase64(encoded.substr(b + 1, c - b - 1));
  const auto expected = unbase64(encoded.substr(c + 1));
  if (!salt || !expected || expected->empty() || expected->size() > 64) {
    return false;
  }
  std::vector<unsigned char> got(expected->size());
  if (!pbkdf2(password, salt->data(), salt->size(), iterations, got.data(), got.size())) {
    return false;
  }
  return CRYPTO_memcmp(got.data(), expected->data(), got.size()) == 0;
}

Authenticator::Authenticator(std::vector<UserEntry> users, std::chrono::seconds ttl)
    : users_(std::move(users)), ttl_(ttl) {}

Result<std::string> Authenticator::sign_in(const std::string& user, const std::string& password) {
  const UserEntry* entry = nullptr;
  for (const auto& u : users_) {
    if (u.name == user) {
      entry = &u;
    }
  }
  {
    std::lock_guard lock(mutex_);
    auto& f = failures_[user.substr(0, 64)];
    if (now() < f.locked_until) {
      return Error{Errc::kNotReady, "too many failed sign-ins: wait a minute"};
    }
  }
  // Verify outside the lock (PBKDF2 takes ~0.1 s); an unknown user costs the same time.
  const bool ok = entry != nullptr
                      ? verify_password(password, entry->password_hash)
                      : (verify_password(password, "pbkdf2-sha256$200000$AAAAAAAAAAAAAAAAAAAAAA==$"
                                                   "AAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAA="),
                         false);
  std::lock_guard lock(mutex_);
  const auto t = now();
  if (!ok) {
    auto& f = failures_[user.substr(0, 64)];
    std::erase_if(f.times, [&](Clock::time_point x) { return t - x > kFailureWindow; });
    f.times.push_back(t);
    if (static_cast<int>(f.times.size()) >= kMaxFailures) {
      f.locked_until = t + kLockout;
      f.times.clear();
    }
    return Error{Errc::kInvalidArgument, "unknown user or wrong password"};
  }
  failures_.erase(user);
  std::array<unsigned char, kTokenBytes> raw{};
  if (RAND_bytes(raw.data(), static_cast<int>(raw.size())) != 1) {
    return Error{Errc::kIo, "OpenSSL could not make a session token"};
  }
  std::string token;
  for (const unsigned char byte : raw) {
    token += fmt::format("{:02x}", byte);
  }
  std::erase_if(sessions_, [&](const auto& kv) { return kv.second.expires <= t; });
  sessions_[token] = Session{{entry->name, entry->role}, t + ttl_};
  return token;
}

std::optional<SessionInfo> Authenticator::session(const std::string& token) {
  if (token.size() != 2 * kTokenBytes) {
    return std::nullopt;
  }
  std::lock_guard lock(mutex_);
  auto it = sessions_.find(token);
  if (it == sessions_.end()) {
    return std::nullopt;
  }
  if (it->second.expires <= now()) {
    sessions_.erase(it);
    return std::nullopt;
  }
  return it->second.info;
}

void Authenticator::sign_out(const std::string& token) {
  std::lock_guard lock(mutex_);
  sessions_.erase(token);
}

std::size_t Authenticator::session_count() {
  std::lock_guard lock(mutex_);
  const auto t = now();
  std::erase_if(sessions_, [&](const auto& kv) { return kv.second.expires <= t; });
  return sessions_.size();
}

void Authenticator::advance_clock_for_test(std::chrono::seconds by) {
  std::lock_guard lock(mutex_);
  skew_ += by;
}

std::string cookie_value(const std::string& header, const std::string& name) {
  std::size_t pos = 0;
  while (pos < header.size()) {
    while (pos < header.size() && (header[pos] == ' ' || header[pos] == ';')) {
      ++pos;
    }
    const std::size_t end = std::min(header.find(';', pos), header.size());
    const std::string item = header.substr(pos, end - pos);
    const std::size_t eq = item.find('=');
    if (eq != std::string::npos && item.substr(0, eq) == name) {
      return item.substr(eq + 1);
    }
    pos = end + 1;
  }
  return {};
}

}  // namespace cell::monitor
