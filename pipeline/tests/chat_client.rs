//! The chat client against a real HTTP server on 127.0.0.1 (tests/common): retries with
//! backoff on 429 / 5xx / timeouts / unreadable bodies, giving up after max_retries, no retry
//! on other 4xx, the reply cache (a second ask sends nothing), the key sent only as a Bearer
//! token and scrubbed from errors, bounded concurrency, and the response_format fallback.

mod common;

use std::sync::Arc;
use std::time::Duration;

use common::{MockServer, Reply};
use mesa_pipeline::chat::{ApiKey, ChatClient, Mode};
use mesa_stages::tasks::chat::{CallKind, Chat, ChatError, ChatRequest};
use mesa_stages::tasks::LlmConfig;
use serde_json::json;

const KEY: &str = "sk-mesa-client-test-9f8e7d";

fn config(base_url: &str) -> LlmConfig {
    LlmConfig {
        base_url: base_url.to_owned(),
        model: "mock-model".to_owned(),
        max_retries: 3,
        backoff_initial_s: 0.02,
        backoff_max_s: 0.5,
        timeout_s: 0.5,
        ..LlmConfig::default()
    }
}

fn request(text: &str) -> ChatRequest {
    ChatRequest {
        call: CallKind::Description,
        body: json!({"model": "mock-model", "messages": [{"role": "user", "content": text}],
                     "temperature": 0.0, "max_tokens": 16, "seed": 0}),
    }
}

/// A live client with the test key (the key from the environment is tested end to end in
/// tasks_llm_cli.rs, where the variable is set for the child process only).
fn client(dir: &std::path::Path, config: &LlmConfig) -> ChatClient {
    ChatClient::with_key(dir, config, Mode::Live, Some(ApiKey::new(KEY)))
}

#[test]
fn a_429_then_success_is_retried_after_the_servers_delay() {
    let server = MockServer::start(|_, n| match n {
        0 => Reply::error(429, "slow down").with_header("Retry-After", "0.1"),
        _ => Reply::completion("hello"),
    });
    let dir = tempfile::tempdir().expect("tempdir");
    let client = client(dir.path(), &config(&server.base_url));
    let reply = client.complete(&request("a")).expect("a reply");
    assert_eq!(reply.content, "hello");
    assert_eq!(server.requests(), 2);
    assert_eq!(*client.stats.backoffs_s.lock().expect("lock"), [0.1]);
    let received = server.received();
    assert_eq!(
        received[0].request_line,
        "POST /v1/chat/completions HTTP/1.1"
    );
    assert_eq!(
        received[1].header("authorization").as_deref(),
        Some(&*format!("Bearer {KEY}"))
    );
    assert_eq!(received[1].json()["messages"][0]["content"], "a");
}

#[test]
fn five_hundreds_back_off_exponentially_then_give_up() {
    let server = MockServer::start(|_, _| Reply::error(500, "boom"));
    let dir = tempfile::tempdir().expect("tempdir");
    let cfg = config(&server.base_url);
    let client = client(dir.path(), &cfg);
    let error = client.complete(&request("b")).expect_err("fails");
    let ChatError::Failed(message) = error else {
        panic!("expected a failure")
    };
    assert!(message.contains("HTTP 500"), "{message}");
    assert!(message.contains("gave up after 4 attempts"), "{message}");
    assert_eq!(server.requests(), 4, "1 + max_retries");
    let backoffs = client.stats.backoffs_s.lock().expect("lock").clone();
    assert_eq!(backoffs.len(), 3);
    // Doubling with jitter in [0.5, 1): 0.02·2^k·[0.5, 1).
    for (k, delay) in backoffs.iter().enumerate() {
        let full = 0.02 * 2f64.powi(k as i32);
        assert!(*delay >= full * 0.5 && *delay < full, "retry {k}: {delay}");
    }
    assert!(
        !dir.path().join(".mesa/cache/chat").exists(),
        "failures are not cached"
    );
}

#[test]
fn timeouts_and_unreadable_bodies_are_retried() {
    let server = MockServer::start(|_, n| match n {
        0 => Reply::completion("late").after(Duration::from_millis(1500)),
        1 => Reply {
            status: 200,
            headers: vec![],
            body: "<html>gateway hiccup</html>".to_owned(),
            delay: Duration::ZERO,
        },
        _ => Reply::completion("on time"),
    });
    let dir = tempfile::tempdir().expect("tempdir");
    let client = client(dir.path(), &config(&server.base_url));
    let reply = client.complete(&request("c")).expect("a reply");
    assert_eq!(reply.content, "on time");
    assert_eq!(server.requests(), 3);
    assert_eq!(
        client
            .stats
            .retries
            .load(std::sync::atomic::Ordering::SeqCst),
        2
    );
}

#[test]
fn replies_are_cached_by_request_so_asking_again_sends_nothing() {
    let server = MockServer::start(|r, _| {
        Reply::completion(&format!("echo {}", r.json()["messages"][0]["content"]))
    });
    let dir = tempfile::tempdir().expect("tempdir");
    let cfg = config(&server.base_url);
    let first = client(dir.path(), &cfg);
    assert_eq!(
        first.complete(&request("d")).expect("reply").content,
        "echo \"d\""
    );
    assert_eq!(server.requests(), 1);
    // A new client (a rerun) over the same dataset: served from the cache.
    let again = client(dir.path(), &cfg);
    assert_eq!(
        again.complete(&request("d")).expect("reply").content,
        "echo \"d\""
    );
    assert_eq!(server.requests(), 1, "no request the second time");
    assert_eq!(
        again
            .stats
            .cache_hits
            .load(std::sync::atomic::Ordering::SeqCst),
        1
    );
    // Another request is another key.
    again.complete(&request("e")).expect("reply");
    assert_eq!(server.requests(), 2);
    // The cache holds neither the key nor the URL.
    for (_, bytes) in common::all_files(dir.path()) {
        let text = String::from_utf8_lossy(&bytes);
        assert!(!text.contains(KEY) && !text.contains("127.0.0.1"), "{text}");
    }
    // Offline: the cache answers, a miss is pending.
    let offline = ChatClient::new(dir.path(), &cfg, Mode::CacheOnly).expect("client");
    assert!(offline.complete(&request("d")).is_ok());
    assert!(matches!(
        offline.complete(&request("f")),
        Err(ChatError::Pending(_))
    ));
    assert_eq!(server.requests(), 2);
}

#[test]
fn other_client_errors_fail_at_once_and_never_show_the_key() {
    // A hostile or careless server echoes the credentials it got.
    let server = MockServer::start(|r, _| {
        Reply::error(
            401,
            &format!(
                "invalid key {}",
                r.header("authorization").unwrap_or_default()
            ),
        )
    });
    let dir = tempfile::tempdir().expect("tempdir");
    let client = client(dir.path(), &config(&server.base_url));
    let ChatError::Failed(message) = client.complete(&request("g")).expect_err("401") else {
        panic!("expected a failure")
    };
    assert_eq!(server.requests(), 1, "a 401 is not retried");
    assert!(message.contains("HTTP 401"), "{message}");
    assert!(
        message.contains("<redacted>") && !message.contains(KEY),
        "{message}"
    );
    assert!(!format!("{client:?}").contains(KEY));
}

#[test]
fn a_missing_key_variable_is_a_clear_error() {
    let mut cfg = config("http://127.0.0.1:9/v1");
    cfg.api_key_env = "MESA_CHAT_CLIENT_TEST_UNSET".to_owned();
    let dir = tempfile::tempdir().expect("tempdir");
    let error = ChatClient::new(dir.path(), &cfg, Mode::Live).expect_err("no key");
    assert!(
        error.contains("MESA_CHAT_CLIENT_TEST_UNSET") && error.contains("not set"),
        "{error}"
    );
    // Offline batches need no key.
    assert!(ChatClient::new(dir.path(), &cfg, Mode::CacheOnly).is_ok());
}

#[test]
fn requests_in_flight_stay_within_max_concurrency() {
    let server = MockServer::start(|_, _| Reply::completion("ok").after(Duration::from_millis(60)));
    let dir = tempfile::tempdir().expect("tempdir");
    let mut cfg = config(&server.base_url);
    cfg.max_concurrency = 3;
    let client = Arc::new(client(dir.path(), &cfg));
    let threads: Vec<_> = (0..12)
        .map(|i| {
            let client = client.clone();
            std::thread::spawn(move || client.complete(&request(&format!("p{i}"))).expect("reply"))
        })
        .collect();
    for t in threads {
        t.join().expect("thread");
    }
    assert_eq!(server.requests(), 12);
    let peak = client
        .stats
        .peak_in_flight
        .load(std::sync::atomic::Ordering::SeqCst);
    assert!((2..=3).contains(&peak), "peak {peak}");
}

#[test]
fn a_server_refusing_response_format_is_asked_without_it() {
    let server = MockServer::start(|r, _| {
        if r.json().get("response_format").is_some() {
            Reply::error(
                400,
                "Unrecognized request argument supplied: response_format",
            )
        } else {
            Reply::completion("{\"tasks\": []}")
        }
    });
    let dir = tempfile::tempdir().expect("tempdir");
    let cfg = config(&server.base_url);
    let first = client(dir.path(), &cfg);
    let mut json_request = request("h");
    json_request.body["response_format"] = json!({"type": "json_object"});
    assert_eq!(
        first.complete(&json_request).expect("reply").content,
        "{\"tasks\": []}"
    );
    assert_eq!(server.requests(), 2);
    assert_eq!(first.warnings().len(), 1);
    assert!(first.warnings()[0].contains("json_mode = false"));
    // Cached under the request as asked: a rerun sends nothing.
    let rerun = client(dir.path(), &cfg);
    rerun.complete(&json_request).expect("cached");
    assert_eq!(server.requests(), 2);
}
