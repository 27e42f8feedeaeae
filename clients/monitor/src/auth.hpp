#pragma once

#include <chrono>
#include <map>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "cell/common/result.hpp"
#include "monitor_config.hpp"

/// Operators' sign-in for the monitor: PBKDF2-HMAC-SHA256 password hashes (OpenSSL's
/// PKCS5_PBKDF2_HMAC) in config/monitor.yaml, random session tokens carried in an HttpOnly,
/// SameSite=Strict cookie.
namespace cell::monitor {

/// Default PBKDF2 iteration count for new hashes (OWASP 2023 suggests 600,000 for SHA-256;
/// sign-in is rare here, and 200,000 costs about 0.1 s on this machine's cores).
inline constexpr int kDefaultIterations = 200'000;

/// "pbkdf2-sha256$<iterations>$<salt, base64>$<hash, base64>" for `password`, with a fresh
/// 16-byte random salt. Errors: kInvalidArgument for iterations < 1000 or an empty password.
Result<std::string> hash_password(const std::string& password, int iterations = kDefaultIterations);

/// True when `password` matches `encoded` (constant-time comparison). A malformed `encoded`
/// never matches.
bool verify_password(const std::string& password, const std::string& encoded);

/// Who a session belongs to.
struct SessionInfo {
  std::string user;
  std::string role;  ///< "operator" or "viewer"
};

/// The signed-in sessions and the users who may sign in. Thread-safe (one mutex).
class Authenticator {
 public:
  using Clock = std::chrono::steady_clock;

  /// `ttl`: how long a session lives after sign-in.
  Authenticator(std::vector<UserEntry> users, std::chrono::seconds ttl);

  /// Checks the password; on success a new session token (64 hex characters). After 5
  /// failures for one user within 60 s, further attempts for that user are refused for 60 s
  /// (kNotReady "too many failed sign-ins"). Errors: kInvalidArgument "unknown user or wrong
  /// password" (the same for both, so names cannot be probed).
  Result<std::string> sign_in(const std::string& user, const std::string& password);

  /// The session of `token`, or nullopt when unknown or expired.
  std::optional<SessionInfo> session(const std::string& token);

  /// Ends a session (no-op for an unknown token).
  void sign_out(const std::string& token);

  /// Whether any user is configured (without users nobody can command).
  bool has_users() const noexcept { return !users_.empty(); }

  /// Sessions alive now.
  std::size_t session_count();

  /// For tests: lets the clock jump (added to every reading).
  void advance_clock_for_test(std::chrono::seconds by);

 private:
  struct Session {
    SessionInfo info;
    Clock::time_point expires;
  };
  struct Failures {
    std::vector<Clock::time_point> times;
    Clock::time_point locked_until{};
  };
  Clock::time_point now() const { return Clock::now() + skew_; }

  std::vector<UserEntry> users_;
  std::chrono::seconds ttl_;
  std::mutex mutex_;
  std::map<std::string, Session> sessions_;
  std::map<std::string, Failures> failures_;
  Clock::duration skew_{};
};

/// The value of cookie `name` in a Cookie header ("a=1; cell_session=abc"), or "".
std::string cookie_value(const std::string& header, const std::string& name);

}  // namespace cell::monitor
