//! The chat client of `mesa tasks`: any OpenAI-compatible `/chat/completions` endpoint, with
//! bounded concurrency, retries with exponential backoff, and a content-addressed reply cache
//! under the dataset so that a rerun never pays twice; and the offline batches (OpenAI Batch
//! JSONL out, the provider's output JSONL in, joined by `custom_id`).
//!
//! - The API key comes from the environment variable `[tasks.llm] api_key_env` names. It is
//!   sent as a Bearer token and nowhere else: it is not in the request body (so not in batch
//!   files or cache keys), not in any message (error texts from a server are scrubbed of it),
//!   and [`ApiKey`] prints as `<redacted>`. A reply that holds the key (a server echoing it)
//!   has it replaced by `<redacted>` in the one place every reply passes before anything is
//!   written, [`ReplyCache::put`] (direct replies and batch imports alike; entries cached
//!   before are scrubbed when read): the cache entry and the rejects of such a reply say
//!   `"redacted": true`, and its scene gets a warning.
//! - The cache key is the SHA-256 of the request body's canonical JSON (sorted keys): model,
//!   messages (images included), sampling parameters. The endpoint URL is not part of it: the
//!   same model name behind another URL is taken as the same model, which is what lets batch
//!   replies serve the direct path and the other way round. Replies are cached as received,
//!   before validation, so a rejected reply is not paid for again either; a new attempt changes
//!   the seed, hence the key.
//! - Retried: HTTP 408, 429 and 5xx, timeouts, broken connections, response bodies that are
//!   not a chat completion. Not retried: other 4xx (the request itself is wrong). The delay
//!   doubles from `backoff_initial_s` up to `backoff_max_s`, times a jitter in [0.5, 1) drawn
//!   from the request digest; a `Retry-After` header (seconds) replaces it, within the same
//!   bound.

use std::collections::BTreeMap;
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Condvar, Mutex};
use std::time::Duration;

// The cached reply is a mesa-schemas artifact, so `mesa validate` knows it.
use mesa_schemas::artifacts::{CachedChatReply as CachedReply, CHAT_REPLY_SCHEMA as CACHE_SCHEMA};
use mesa_stages::tasks::chat::{Chat, ChatError, ChatReply, ChatRequest};
use mesa_stages::tasks::LlmConfig;
use serde_json::Value;

use crate::fsio::{sha256_hex, write_atomic};

/// The request URL of OpenAI Batch input lines.
pub const BATCH_URL: &str = "/v1/chat/completions";

/// An API key. It prints as `<redacted>`.
#[derive(Clone)]
pub struct ApiKey(String);

impl std::fmt::Debug for ApiKey {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("ApiKey(<redacted>)")
    }
}

impl ApiKey {
    /// A key given directly.
    pub fn new(key: impl Into<String>) -> Self {
        Self(key.into())
    }

    /// The key in the environment variable `var`; `Ok(None)` when `var` is "" (no key sent).
    pub fn from_env(var: &str) -> Result<Option<Self>, String> {
        if var.is_empty() {
            return Ok(None);
        }
        match std::env::var(var) {
            Ok(key) if !key.trim().is_empty() => Ok(Some(Self(key.trim().to_owned()))),
            Ok(_) => Err(format!(
                "the environment variable {var} (named by [tasks.llm] api_key_env) is empty \
                 (set it to the API key, or set api_key_env = \"\" for a server without keys)"
            )),
            Err(_) => Err(format!(
                "the environment variable {var} (named by [tasks.llm] api_key_env) is not set \
                 (export it with the API key, or set api_key_env = \"\" for a server without \
                 keys)"
            )),
        }
    }

    /// `text` with every occurrence of the key replaced by `<redacted>`.
    pub fn scrub(&self, text: &str) -> String {
        if self.0.is_empty() {
            text.to_owned()
        } else {
            text.replace(&self.0, "<redacted>")
        }
    }

    /// Whether `text` holds the key.
    pub fn is_in(&self, text: &str) -> bool {
        !self.0.is_empty() && text.contains(&self.0)
    }
}

/// A reply (and the model the server named) with the key replaced by `<redacted>`, marked
/// redacted when it held the key.
fn redacted(
    key: Option<&ApiKey>,
    mut reply: ChatReply,
    model: Option<String>,
) -> (ChatReply, Option<String>) {
    let Some(key) = key else {
        return (reply, model);
    };
    let in_model = model.as_deref().is_some_and(|m| key.is_in(m));
    if key.is_in(&reply.content) || in_model {
        reply.content = key.scrub(&reply.content);
        reply.redacted = true;
    }
    (reply, model.map(|m| key.scrub(&m)))
}

/// The digest of a request: SHA-256 of its body's canonical JSON.
pub fn request_digest(request: &ChatRequest) -> String {
    // serde_json's maps are sorted in this build (a test in mesa-schemas pins it), so the same
    // body always gives the same bytes.
    sha256_hex(&serde_json::to_vec(&request.body).unwrap_or_default())
}

/// The content-addressed reply cache of a dataset. With the API key, it redacts the key
/// from every reply it stores or returns.
#[derive(Debug, Clone)]
pub struct ReplyCache {
    dir: PathBuf,
    key: Option<ApiKey>,
}

impl ReplyCache {
    /// The cache of a dataset folder.
    pub fn of_dataset(dataset: &Path) -> Self {
        Self {
            dir: dataset.join(mesa_stages::paths::dataset::CHAT_CACHE),
            key: None,
        }
    }

    /// The cache, redacting `key` from replies.
    pub fn with_key(mut self, key: Option<ApiKey>) -> Self {
        self.key = key;
        self
    }

    fn path(&self, digest: &str) -> PathBuf {
        self.dir
            .join(&digest[..2.min(digest.len())])
            .join(format!("{digest}.json"))
    }

    /// The cached reply to a request digest. An unreadable entry is an error naming the file
    /// (delete it to ask again).
    pub fn get(&self, digest: &str) -> Result<Option<ChatReply>, String> {
        let path = self.path(digest);
        let bytes = match std::fs::read(&path) {
            Ok(bytes) => bytes,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
            Err(e) => {
                return Err(format!(
                    "{}: cannot read the cached reply: {e}",
                    path.display()
                ))
            }
        };
        let cached: CachedReply = serde_json::from_slice(&bytes).map_err(|e| {
            format!(
                "{}: not a cached reply ({e}); delete the file to ask the model again",
                path.display()
            )
        })?;
        let reply = ChatReply {
            content: cached.content,
            finish_reason: cached.finish_reason,
            redacted: cached.redacted,
        };
        // An entry written before redaction existed, or with another key: scrub it in place.
        let (clean, model) = redacted(self.key.as_ref(), reply.clone(), cached.model.clone());
        if clean.redacted && !reply.redacted {
            return self.put(digest, &clean, model.as_deref()).map(Some);
        }
        Ok(Some(clean))
    }

    /// Stores a reply (atomically) with the key redacted from it, and returns what was stored
    /// (marked redacted when it held the key).
    pub fn put(
        &self,
        digest: &str,
        reply: &ChatReply,
        model: Option<&str>,
    ) -> Result<ChatReply, String> {
        let (reply, model) = redacted(self.key.as_ref(), reply.clone(), model.map(str::to_owned));
        let cached = CachedReply {
            schema: CACHE_SCHEMA.to_owned(),
            request_sha256: digest.to_owned(),
            model,
            content: reply.content.clone(),
            finish_reason: reply.finish_reason.clone(),
            redacted: reply.redacted,
        };
        let path = self.path(digest);
        let bytes = mesa_schemas::json::to_sorted_pretty(&cached).map_err(|e| e.to_string())?;
        write_atomic(&path, &bytes)
            .map_err(|e| format!("{}: cannot write the cached reply: {e}", path.display()))?;
        Ok(reply)
    }

    /// Whether a reply to the digest is cached.
    pub fn contains(&self, digest: &str) -> bool {
        self.path(digest).is_file()
    }
}

/// The reply text of a chat completion (`choices[0].message.content`), with the model the
/// server reports. The error says what is missing.
pub fn reply_from_completion(body: &Value) -> Result<(ChatReply, Option<String>), String> {
    let choice = body
        .get("choices")
        .and_then(Value::as_array)
        .and_then(|c| c.first())
        .ok_or("no choices[0] in the completion")?;
    let message = choice.get("message").ok_or("no choices[0].message")?;
    let content = match message.get("content") {
        Some(Value::String(text)) => text.clone(),
        Some(Value::Array(parts)) => parts
            .iter()
            .filter_map(|p| p.get("text").and_then(Value::as_str))
            .collect::<Vec<_>>()
            .join(""),
        _ => {
            let refusal = message.get("refusal").and_then(Value::as_str);
            return Err(match refusal {
                Some(r) => format!("the model refused: {r}"),
                None => "choices[0].message.content is missing".to_owned(),
            });
        }
    };
    let finish_reason = choice
        .get("finish_reason")
        .and_then(Value::as_str)
        .map(str::to_owned);
    let model = body.get("model").and_then(Value::as_str).map(str::to_owned);
    Ok((
        ChatReply {
            content,
            finish_reason,
            redacted: false,
        },
        model,
    ))
}

/// A counting semaphore: at most `limit` holders at once.
#[derive(Debug)]
struct Slots {
    free: Mutex<usize>,
    freed: Condvar,
}

struct Slot<'a>(&'a Slots);

impl Slots {
    fn new(limit: usize) -> Self {
        Self {
            free: Mutex::new(limit.max(1)),
            freed: Condvar::new(),
        }
    }

    fn acquire(&self) -> Slot<'_> {
        let mut free = self.free.lock().unwrap_or_else(|e| e.into_inner());
        while *free == 0 {
            free = self.freed.wait(free).unwrap_or_else(|e| e.into_inner());
        }
        *free -= 1;
        Slot(self)
    }
}

impl Drop for Slot<'_> {
    fn drop(&mut self) {
        let mut free = self.0.free.lock().unwrap_or_else(|e| e.into_inner());
        *free += 1;
        self.0.freed.notify_one();
    }
}

/// What the client did, for summaries and tests.
#[derive(Debug, Default)]
pub struct ChatStats {
    /// HTTP requests sent (retries included).
    pub requests: AtomicU64,
    /// Replies served from the cache.
    pub cache_hits: AtomicU64,
    /// Retries after a transient failure.
    pub retries: AtomicU64,
    /// Requests that failed for good.
    pub failures: AtomicU64,
    /// Requests at most in flight at the same time.
    pub peak_in_flight: AtomicU64,
    in_flight: AtomicU64,
    /// Every backoff delay slept, in seconds, in order.
    pub backoffs_s: Mutex<Vec<f64>>,
}

impl ChatStats {
    /// `N requests, N cache hits, N retries, N failed`.
    pub fn summary(&self) -> String {
        format!(
            "{} requests, {} cache hits, {} retries, {} failed",
            self.requests.load(Ordering::Relaxed),
            self.cache_hits.load(Ordering::Relaxed),
            self.retries.load(Ordering::Relaxed),
            self.failures.load(Ordering::Relaxed)
        )
    }
}

/// Whether the client may send requests.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mode {
    /// Send what the cache does not hold.
    Live,
    /// Offline batches: answer from the cache only; a miss is [`ChatError::Pending`].
    CacheOnly,
}

enum SendError {
    /// Worth retrying (with the server's Retry-After, in seconds).
    Transient(String, Option<f64>),
    /// The server does not take `response_format`.
    NoJsonMode(String),
    /// Not worth retrying.
    Fatal(String),
}

/// The chat client.
pub struct ChatClient {
    agent: ureq::Agent,
    endpoint: String,
    key: Option<ApiKey>,
    config: LlmConfig,
    cache: ReplyCache,
    mode: Mode,
    slots: Slots,
    no_json_mode: AtomicBool,
    /// What it did.
    pub stats: ChatStats,
    warnings: Mutex<Vec<String>>,
}

impl std::fmt::Debug for ChatClient {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ChatClient")
            .field("endpoint", &self.endpoint)
            .field("model", &self.config.model)
            .field("key", &self.key)
            .field("mode", &self.mode)
            .finish_non_exhaustive()
    }
}

impl ChatClient {
    /// A client of `config`'s endpoint with the dataset's cache. `Live` needs the key (when
    /// `api_key_env` names one); `CacheOnly` reads no key and sends nothing.
    pub fn new(dataset: &Path, config: &LlmConfig, mode: Mode) -> Result<Self, String> {
        let key = match mode {
            Mode::Live => ApiKey::from_env(&config.api_key_env)?,
            // Nothing is sent; the key, when set, only serves to redact batch replies.
            Mode::CacheOnly => ApiKey::from_env(&config.api_key_env).ok().flatten(),
        };
        Ok(Self::with_key(dataset, config, mode, key))
    }

    /// A client with the key given (`None`: no Authorization header).
    pub fn with_key(dataset: &Path, config: &LlmConfig, mode: Mode, key: Option<ApiKey>) -> Self {
        let agent_config = ureq::Agent::config_builder()
            .timeout_global(Some(Duration::from_secs_f64(config.timeout_s.max(0.001))))
            .http_status_as_error(false)
            .build();
        Self {
            agent: ureq::Agent::new_with_config(agent_config),
            endpoint: format!("{}/chat/completions", config.base_url.trim_end_matches('/')),
            config: config.clone(),
            cache: ReplyCache::of_dataset(dataset).with_key(key.clone()),
            key,
            mode,
            slots: Slots::new(config.max_concurrency),
            no_json_mode: AtomicBool::new(false),
            stats: ChatStats::default(),
            warnings: Mutex::new(Vec::new()),
        }
    }

    /// The reply cache.
    pub fn cache(&self) -> &ReplyCache {
        &self.cache
    }

    /// Warnings about the endpoint (once each), like a server refusing `response_format`.
    pub fn warnings(&self) -> Vec<String> {
        self.warnings
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .clone()
    }

    fn scrub(&self, text: &str) -> String {
        match &self.key {
            Some(key) => key.scrub(text),
            None => text.to_owned(),
        }
    }

    fn backoff_s(&self, retry: u32, digest: &str, retry_after_s: Option<f64>) -> f64 {
        let bound = self.config.backoff_max_s;
        if let Some(after) = retry_after_s {
            return after.clamp(0.0, bound);
        }
        let doubled = self.config.backoff_initial_s * 2f64.powi(retry.min(30) as i32);
        // Jitter in [0.5, 1) from the digest, so that workers hit by the same 429 spread out.
        let seed = u64::from_str_radix(&digest[..8.min(digest.len())], 16).unwrap_or(0);
        let mixed = seed
            .wrapping_add(u64::from(retry))
            .wrapping_mul(0x9e37_79b9_7f4a_7c15);
        let jitter = 0.5 + 0.5 * ((mixed >> 11) as f64 / (1u64 << 53) as f64);
        (doubled * jitter).min(bound)
    }

    fn send_once(&self, body: &[u8]) -> Result<(ChatReply, Option<String>), SendError> {
        let _slot = self.slots.acquire();
        let now = self.stats.in_flight.fetch_add(1, Ordering::SeqCst) + 1;
        self.stats.peak_in_flight.fetch_max(now, Ordering::SeqCst);
        self.stats.requests.fetch_add(1, Ordering::Relaxed);
        let result = self.post(body);
        self.stats.in_flight.fetch_sub(1, Ordering::SeqCst);
        result
    }

    fn post(&self, body: &[u8]) -> Result<(ChatReply, Option<String>), SendError> {
        let mut request = self
            .agent
            .post(&self.endpoint)
            .header("Content-Type", "application/json");
        if let Some(key) = &self.key {
            request = request.header("Authorization", &format!("Bearer {}", key.0));
        }
        let mut response = match request.send(body) {
            Ok(response) => response,
            Err(e) => {
                let message = self.scrub(&e.to_string());
                return Err(match e {
                    ureq::Error::Timeout(_) => SendError::Transient(
                        format!("timed out after {} s", self.config.timeout_s),
                        None,
                    ),
                    ureq::Error::BadUri(_)
                    | ureq::Error::RequireHttpsOnly(_)
                    | ureq::Error::InvalidProxyUrl
                    | ureq::Error::TlsRequired
                    | ureq::Error::Rustls(_)
                    | ureq::Error::Tls(_) => {
                        SendError::Fatal(format!("{}: {message}", self.endpoint))
                    }
                    _ => SendError::Transient(format!("{}: {message}", self.endpoint), None),
                });
            }
        };
        let status = response.status().as_u16();
        let retry_after = response
            .headers()
            .get("retry-after")
            .and_then(|v| v.to_str().ok())
            .and_then(|v| v.trim().parse::<f64>().ok());
        let text = match response.body_mut().read_to_string() {
            Ok(text) => text,
            Err(e) => {
                return Err(SendError::Transient(
                    format!(
                        "HTTP {status}: unreadable response body: {}",
                        self.scrub(&e.to_string())
                    ),
                    retry_after,
                ))
            }
        };
        let excerpt = || {
            let scrubbed = self.scrub(text.trim());
            let mut cut: String = scrubbed.chars().take(300).collect();
            if scrubbed.chars().count() > 300 {
                cut.push_str("...");
            }
            cut
        };
        match status {
            200..=299 => {
                let value: Value = serde_json::from_str(&text).map_err(|e| {
                    SendError::Transient(
                        format!(
                            "HTTP {status} with a body that is not JSON ({e}): {}",
                            excerpt()
                        ),
                        None,
                    )
                })?;
                reply_from_completion(&value).map_err(|why| {
                    SendError::Transient(format!("HTTP {status}: {why}: {}", excerpt()), None)
                })
            }
            408 | 429 | 500..=599 => Err(SendError::Transient(
                format!("HTTP {status}: {}", excerpt()),
                retry_after,
            )),
            400 if text.contains("response_format") => {
                Err(SendError::NoJsonMode(format!("HTTP 400: {}", excerpt())))
            }
            _ => Err(SendError::Fatal(format!(
                "HTTP {status} from {}: {}",
                self.endpoint,
                excerpt()
            ))),
        }
    }

    fn send(&self, request: &ChatRequest, digest: &str) -> Result<ChatReply, ChatError> {
        let mut body = request.body.clone();
        if self.no_json_mode.load(Ordering::Relaxed) {
            if let Some(map) = body.as_object_mut() {
                map.remove("response_format");
            }
        }
        let mut retries = 0u32;
        loop {
            let bytes = serde_json::to_vec(&body).map_err(|e| ChatError::Failed(e.to_string()))?;
            match self.send_once(&bytes) {
                Ok((reply, model)) => {
                    // What is returned is what was stored: the key redacted.
                    return self
                        .cache
                        .put(digest, &reply, model.as_deref())
                        .map_err(ChatError::Failed);
                }
                Err(SendError::NoJsonMode(why)) if body.get("response_format").is_some() => {
                    self.no_json_mode.store(true, Ordering::Relaxed);
                    let mut warnings = self.warnings.lock().unwrap_or_else(|e| e.into_inner());
                    if warnings.is_empty() {
                        let warning = format!(
                            "{} refuses response_format ({why}); sending without it (set \
                             [tasks.llm] json_mode = false to stop asking)",
                            self.endpoint
                        );
                        tracing::warn!("{warning}");
                        warnings.push(warning);
                    }
                    if let Some(map) = body.as_object_mut() {
                        map.remove("response_format");
                    }
                }
                Err(SendError::NoJsonMode(why) | SendError::Fatal(why)) => {
                    self.stats.failures.fetch_add(1, Ordering::Relaxed);
                    return Err(ChatError::Failed(why));
                }
                Err(SendError::Transient(why, retry_after)) => {
                    if retries >= self.config.max_retries {
                        self.stats.failures.fetch_add(1, Ordering::Relaxed);
                        return Err(ChatError::Failed(format!(
                            "{why} (gave up after {} attempts)",
                            retries + 1
                        )));
                    }
                    let delay = self.backoff_s(retries, digest, retry_after);
                    tracing::warn!(
                        "{why}; retrying in {delay:.2} s ({} of {})",
                        retries + 1,
                        self.config.max_retries
                    );
                    self.stats
                        .backoffs_s
                        .lock()
                        .unwrap_or_else(|e| e.into_inner())
                        .push(delay);
                    self.stats.retries.fetch_add(1, Ordering::Relaxed);
                    std::thread::sleep(Duration::from_secs_f64(delay));
                    retries += 1;
                }
            }
        }
    }
}

impl Chat for ChatClient {
    fn complete(&self, request: &ChatRequest) -> Result<ChatReply, ChatError> {
        let digest = request_digest(request);
        if let Some(reply) = self.cache.get(&digest).map_err(ChatError::Failed)? {
            self.stats.cache_hits.fetch_add(1, Ordering::Relaxed);
            return Ok(reply);
        }
        match self.mode {
            Mode::CacheOnly => Err(ChatError::Pending(Box::new(request.clone()))),
            Mode::Live => self.send(request, &digest),
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Offline batches.

/// The `custom_id` of a request in batch files: `mesa-` and the first 48 hex digits of its
/// digest (OpenAI-compatible providers accept it; some limit ids to 64 characters).
pub fn custom_id(digest: &str) -> String {
    format!("mesa-{}", &digest[..48.min(digest.len())])
}

/// One line of an OpenAI Batch input file.
pub fn batch_line(request: &ChatRequest) -> Value {
    serde_json::json!({
        "custom_id": custom_id(&request_digest(request)),
        "method": "POST",
        "url": BATCH_URL,
        "body": request.body,
    })
}

/// Writes the requests as an OpenAI Batch input file (one line per distinct request, in the
/// given order), atomically. Returns the number of lines.
pub fn write_batch(path: &Path, requests: &[ChatRequest]) -> std::io::Result<usize> {
    let mut seen = std::collections::BTreeSet::new();
    let mut bytes = Vec::new();
    for request in requests {
        let line = batch_line(request);
        if !seen.insert(line["custom_id"].as_str().unwrap_or_default().to_owned()) {
            continue;
        }
        serde_json::to_writer(&mut bytes, &line).map_err(std::io::Error::other)?;
        bytes.write_all(b"\n")?;
    }
    write_atomic(path, &bytes)?;
    Ok(seen.len())
}

/// What reading a provider's batch output did.
#[derive(Debug, Default, Clone, PartialEq, Eq)]
pub struct BatchImport {
    /// Replies stored in the cache.
    pub stored: usize,
    /// Lines whose reply the cache already held.
    pub already_cached: usize,
    /// Lines that could not be used, each `<file>:<line>: <custom_id>: <why>` (their requests
    /// stay pending and go into the next batch).
    pub failed: Vec<String>,
}

/// The custom ids of `requests`, each to its request's digest: what [`import_batch`] joins a
/// provider's output lines to.
pub fn pending_by_id<'a>(
    requests: impl IntoIterator<Item = &'a ChatRequest>,
) -> BTreeMap<String, String> {
    requests
        .into_iter()
        .map(|request| {
            let digest = request_digest(request);
            (custom_id(&digest), digest)
        })
        .collect()
}

/// What [`import_batch_files`] did: a line per file (and one per failed line) for the caller
/// to show, and the count of failed lines.
#[derive(Debug, Default)]
pub struct BatchFilesImport {
    /// `FILE: N replies stored, N already cached, N lines failed`, then `  failed ...` lines.
    pub lines: Vec<String>,
    /// Lines of the files that could not be used.
    pub failed: usize,
}

/// Reads each provider batch output file (`--batch-in`, bounded like a records file) and
/// stores its replies in `cache` ([`import_batch`]); an unreadable file is a usage error.
pub fn import_batch_files(
    files: &[PathBuf],
    pending: &BTreeMap<String, String>,
    cache: &ReplyCache,
) -> anyhow::Result<BatchFilesImport> {
    let mut out = BatchFilesImport::default();
    for file in files {
        let text =
            crate::fsio::read_text_bounded(file, crate::fsio::RECORDS_LIMIT).map_err(|e| {
                crate::exit::usage(format!(
                    "{}: cannot read the batch output: {e}",
                    file.display()
                ))
            })?;
        let report = import_batch(file, &text, pending, cache);
        out.lines.push(format!(
            "{}: {} replies stored, {} already cached, {} lines failed",
            file.display(),
            report.stored,
            report.already_cached,
            report.failed.len()
        ));
        out.lines
            .extend(report.failed.iter().map(|f| format!("  failed {f}")));
        out.failed += report.failed.len();
    }
    Ok(out)
}

/// Reads a provider's batch output JSONL (`{"custom_id", "response": {"status_code", "body"},
/// "error"}` per line) and stores each successful reply in the cache under the request it
/// answers. Lines are joined to requests by `custom_id`, never by position; `pending` maps the
/// custom ids of the requests this dataset is waiting for to their digests.
pub fn import_batch(
    path: &Path,
    text: &str,
    pending: &BTreeMap<String, String>,
    cache: &ReplyCache,
) -> BatchImport {
    let mut report = BatchImport::default();
    let mut seen = std::collections::BTreeSet::new();
    for (i, line) in text.lines().enumerate() {
        if line.trim().is_empty() {
            continue;
        }
        let at = format!("{}:{}", path.display(), i + 1);
        let value: Value = match serde_json::from_str(line) {
            Ok(v) => v,
            Err(e) => {
                report.failed.push(format!("{at}: not JSON ({e})"));
                continue;
            }
        };
        let Some(id) = value.get("custom_id").and_then(Value::as_str) else {
            report.failed.push(format!("{at}: no custom_id"));
            continue;
        };
        if !seen.insert(id.to_owned()) {
            report.failed.push(format!(
                "{at}: {id}: appears again (the first line was used)"
            ));
            continue;
        }
        let Some(digest) = pending.get(id) else {
            if pending.is_empty() || !id.starts_with("mesa-") {
                report.failed.push(format!(
                    "{at}: {id}: not a request of this dataset (expected custom ids written by \
                     `mesa tasks --batch-out`)"
                ));
            } else {
                report.failed.push(format!(
                    "{at}: {id}: matches no pending request (already answered, or the inputs, \
                     prompts or [tasks] configuration changed since the batch was written)"
                ));
            }
            continue;
        };
        if cache.contains(digest) {
            report.already_cached += 1;
            continue;
        }
        if let Some(error) = value.get("error").filter(|e| !e.is_null()) {
            let code = error.get("code").and_then(Value::as_str).unwrap_or("error");
            let message = error.get("message").and_then(Value::as_str).unwrap_or("");
            report.failed.push(format!("{at}: {id}: {code}: {message}"));
            continue;
        }
        let Some(response) = value.get("response").filter(|r| !r.is_null()) else {
            report.failed.push(format!("{at}: {id}: no response"));
            continue;
        };
        let status = response
            .get("status_code")
            .and_then(Value::as_u64)
            .unwrap_or(0);
        let body = response.get("body").cloned().unwrap_or(Value::Null);
        if status != 200 {
            let message = body
                .pointer("/error/message")
                .and_then(Value::as_str)
                .unwrap_or("");
            report
                .failed
                .push(format!("{at}: {id}: HTTP {status}: {message}"));
            continue;
        }
        match reply_from_completion(&body) {
            Ok((reply, model)) => match cache.put(digest, &reply, model.as_deref()) {
                Ok(_) => report.stored += 1,
                Err(e) => report.failed.push(format!("{at}: {id}: {e}")),
            },
            Err(why) => report.failed.push(format!("{at}: {id}: {why}")),
        }
    }
    report
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys_never_print() {
        let key = ApiKey("sk-secret-123".to_owned());
        assert_eq!(format!("{key:?}"), "ApiKey(<redacted>)");
        assert_eq!(key.scrub("bad key sk-secret-123!"), "bad key <redacted>!");
    }

    #[test]
    fn completions_give_their_text_or_say_what_is_missing() {
        let body = serde_json::json!({"model": "m-1", "choices": [{"message": {"role": "assistant",
            "content": "hi"}, "finish_reason": "stop"}]});
        let (reply, model) = reply_from_completion(&body).expect("reply");
        assert_eq!(reply.content, "hi");
        assert_eq!(reply.finish_reason.as_deref(), Some("stop"));
        assert_eq!(model.as_deref(), Some("m-1"));
        assert!(reply_from_completion(&serde_json::json!({"choices": []})).is_err());
        let refused =
            serde_json::json!({"choices": [{"message": {"content": null, "refusal": "no"}}]});
        assert!(reply_from_completion(&refused)
            .expect_err("refusal")
            .contains("refused"));
    }
}
