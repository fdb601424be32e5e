//! What the tasks library asks of a chat backend, and the OpenAI chat-completions request
//! bodies it builds. The HTTP client (retries, backoff, concurrency, the reply cache) and the
//! offline batches implement [`Chat`] in the pipeline crate.

use base64::Engine as _;
use serde_json::{json, Value};

use crate::tasks::prompts::RenderedPrompt;
use crate::tasks::LlmConfig;

/// A rendered view of the scene.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct View {
    /// `front` or `perspective`.
    pub name: String,
    /// The file, relative to the scene folder (`render/front.png`).
    pub file: String,
    /// The PNG bytes.
    pub png: Vec<u8>,
}

/// The kinds of model call: the three of a scene's tasks, and the GPT score of `mesa eval`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum CallKind {
    /// The table description, from the rendered views and the scene graph.
    Description,
    /// The scene's tasks (task info JSON).
    Tasks,
    /// The reasoning text of one task.
    Reasoning,
    /// The GPT score of a generated scene (`mesa eval --gpt-score`).
    GptScore,
}

impl CallKind {
    /// `description`, `tasks`, `reasoning` or `gpt_score` (as rejects and batch files name it).
    pub fn name(self) -> &'static str {
        match self {
            Self::Description => "description",
            Self::Tasks => "tasks",
            Self::Reasoning => "reasoning",
            Self::GptScore => "gpt_score",
        }
    }
}

/// One chat-completions request.
#[derive(Debug, Clone, PartialEq)]
pub struct ChatRequest {
    /// The call it makes.
    pub call: CallKind,
    /// The complete request body (`model`, `messages`, sampling parameters, perhaps
    /// `response_format`), as POSTed to `/chat/completions` and written into batch files. It
    /// never holds the API key.
    pub body: Value,
}

impl ChatRequest {
    /// Whether the body asks for a JSON object reply.
    pub fn json_mode(&self) -> bool {
        self.body.get("response_format").is_some()
    }
}

/// A model reply.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct ChatReply {
    /// The text of `choices[0].message.content`.
    pub content: String,
    /// `choices[0].finish_reason` when the server gave one (`length` means cut at max_tokens).
    pub finish_reason: Option<String>,
    /// Whether the backend found the API key in the reply and replaced it by `<redacted>`
    /// (before caching it): rejects of such a reply say `"redacted": true`, and the scene gets
    /// a warning.
    pub redacted: bool,
}

/// Why a backend gave no reply.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ChatError {
    /// Offline batch mode: the reply is not in the cache yet; the request belongs to the next
    /// batch.
    #[error("no reply yet (offline batch mode: the request goes into the next --batch-out file)")]
    Pending(Box<ChatRequest>),
    /// The endpoint failed for good (after its retries).
    #[error("{0}")]
    Failed(String),
}

/// A chat backend: the HTTP client, or the reply cache alone in batch mode.
pub trait Chat: Sync {
    /// The reply to a request.
    fn complete(&self, request: &ChatRequest) -> Result<ChatReply, ChatError>;
}

/// A `data:image/png;base64,...` URL of PNG bytes.
pub fn png_data_url(png: &[u8]) -> String {
    format!(
        "data:image/png;base64,{}",
        base64::engine::general_purpose::STANDARD.encode(png)
    )
}

/// The request body of a call: the prompt's system and user messages, the images (as base64
/// PNG data URLs after the user text), the sampling parameters of `config`, the seed plus the
/// attempt, and `response_format` when `json` is asked and `config.json_mode` allows it.
pub fn build_request(
    call: CallKind,
    config: &LlmConfig,
    prompt: &RenderedPrompt,
    images: &[View],
    json: bool,
    attempt: u32,
) -> ChatRequest {
    let mut messages = Vec::new();
    if !prompt.system.is_empty() {
        messages.push(json!({"role": "system", "content": prompt.system}));
    }
    if images.is_empty() {
        messages.push(json!({"role": "user", "content": prompt.user}));
    } else {
        let mut parts = vec![json!({"type": "text", "text": prompt.user})];
        for view in images {
            parts.push(json!({
                "type": "image_url",
                "image_url": {"url": png_data_url(&view.png)}
            }));
        }
        messages.push(json!({"role": "user", "content": parts}));
    }
    let mut body = json!({
        "model": config.model,
        "messages": messages,
        "temperature": config.temperature,
        "max_tokens": config.max_tokens,
        "seed": config.seed.wrapping_add(u64::from(attempt)),
    });
    if json && config.json_mode {
        body["response_format"] = json!({"type": "json_object"});
    }
    ChatRequest { call, body }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn images_become_data_urls_after_the_text() {
        let prompt = RenderedPrompt {
            system: "sys".into(),
            user: "describe".into(),
        };
        let view = View {
            name: "front".into(),
            file: "render/front.png".into(),
            png: vec![0x89, b'P', b'N', b'G'],
        };
        let request = build_request(
            CallKind::Description,
            &LlmConfig::default(),
            &prompt,
            std::slice::from_ref(&view),
            false,
            2,
        );
        let content = &request.body["messages"][1]["content"];
        assert_eq!(content[0]["text"], "describe");
        assert_eq!(
            content[1]["image_url"]["url"],
            "data:image/png;base64,iVBORw=="
        );
        assert_eq!(request.body["seed"], 2);
        assert!(!request.json_mode());
        let tasks = build_request(
            CallKind::Tasks,
            &LlmConfig::default(),
            &prompt,
            &[],
            true,
            0,
        );
        assert_eq!(tasks.body["messages"][1]["content"], "describe");
        assert!(tasks.json_mode());
    }
}
