"""Reads mesa's records/ the way the trainers do, and prints what they got as JSON.

Usage: python read_records.py RECORDS_DIR

- LLaMA-Factory: every entry of dataset_info.json is parsed as its DatasetAttr parser does
  (when "columns" is given, a column it does not name is None), the file is loaded with the
  `datasets` library (`load_dataset("json", ...)`, as LLaMA-Factory loads local files), and each
  example goes through the logic of its alpaca / sharegpt converters: the alpaca user turn is
  "\n".join of the non-empty prompt and query columns; a ranking example needs string chosen
  and rejected columns; a sharegpt example alternates user and assistant turns by its tags.
- TRL: trl_sft.jsonl must be conversational language modelling data ("messages": a list of
  {"role", "content"}), trl_dpo.jsonl conversational preference data ("prompt", "chosen",
  "rejected": lists of messages), as TRL's `is_conversational` tells them.

Any mismatch raises; the output is a summary the Rust test checks.
"""

import json
import os
import sys

import datasets


def llamafactory_attr(entry):
    """The attributes LLaMA-Factory's parser gives a dataset_info entry."""
    attr = {
        "formatting": entry.get("formatting", "alpaca"),
        "ranking": entry.get("ranking", False),
        "prompt": "instruction",
        "query": "input",
        "response": "output",
        "chosen": None,
        "rejected": None,
        "messages": "conversations",
        "role_tag": "from",
        "content_tag": "value",
        "user_tag": "human",
        "assistant_tag": "gpt",
    }
    if "columns" in entry:
        names = ["system", "tools", "images", "chosen", "rejected", "kto_tag"]
        if attr["formatting"] == "alpaca":
            names += ["prompt", "query", "response", "history"]
        else:
            names += ["messages"]
        for name in names:
            attr[name] = entry["columns"].get(name)
    if attr["formatting"] == "sharegpt" and "tags" in entry:
        for tag in ["role_tag", "content_tag", "user_tag", "assistant_tag"]:
            attr[tag] = entry["tags"].get(tag)
    return attr


def alpaca_example(attr, example):
    query = []
    if attr["prompt"] and example[attr["prompt"]]:
        query.append(example[attr["prompt"]])
    if attr["query"] and example[attr["query"]]:
        query.append(example[attr["query"]])
    user = "\n".join(query)
    if attr["ranking"]:
        chosen, rejected = example[attr["chosen"]], example[attr["rejected"]]
        assert isinstance(chosen, str) and isinstance(rejected, str), "ranking needs strings"
        return user, [chosen, rejected]
    response = example[attr["response"]]
    assert isinstance(response, str), "alpaca response must be a string"
    return user, [response]


def sharegpt_example(attr, example):
    messages = example[attr["messages"]]
    accept = ([attr["user_tag"]], [attr["assistant_tag"]])
    for i, message in enumerate(messages):
        assert message[attr["role_tag"]] in accept[i % 2], f"turn {i}: {message}"
    assert len(messages) % 2 == 0, "an even number of turns"
    return messages[0][attr["content_tag"]], [m[attr["content_tag"]] for m in messages[1::2]]


def is_conversational(example):
    """TRL's test: a known key holding a list of {"role", "content"} dicts."""
    for key in ["prompt", "chosen", "rejected", "completion", "messages"]:
        if key in example:
            value = example[key]
            if isinstance(value, list) and value and isinstance(value[0], dict):
                return "role" in value[0] and "content" in value[0]
    return False


def main():
    records = sys.argv[1]
    with open(os.path.join(records, "dataset_info.json"), encoding="utf-8") as f:
        info = json.load(f)
    summary = {"llamafactory": {}, "trl": {}}
    for name, entry in sorted(info.items()):
        attr = llamafactory_attr(entry)
        data = datasets.load_dataset(
            "json", data_files=os.path.join(records, entry["file_name"]), split="train"
        )
        firsts = []
        for example in data:
            if attr["formatting"] == "alpaca":
                user, responses = alpaca_example(attr, example)
            else:
                user, responses = sharegpt_example(attr, example)
            assert user and all(responses), f"{name}: an empty turn"
            firsts.append(user)
        summary["llamafactory"][name] = {
            "rows": len(data),
            "columns": sorted(data.column_names),
            "ranking": bool(attr["ranking"]),
            "first_user_turn": firsts[0] if firsts else None,
        }
    for file, keys in [
        ("trl_sft.jsonl", ["messages"]),
        ("trl_test.jsonl", ["messages"]),
        ("trl_dpo.jsonl", ["chosen", "prompt", "rejected"]),
    ]:
        data = datasets.load_dataset("json", data_files=os.path.join(records, file), split="train")
        assert sorted(data.column_names) == keys, f"{file}: {data.column_names}"
        for example in data:
            assert is_conversational(example), f"{file}: not conversational"
        first = data[0]
        user = (first["messages"] if "messages" in first else first["prompt"])[0]
        summary["trl"][file] = {"rows": len(data), "first_user_turn": user["content"]}
    json.dump(summary, sys.stdout, ensure_ascii=False)


if __name__ == "__main__":
    main()
