//! The layout readers on arbitrary bytes: what `mesa validate`, `mesa convert`, `mesa graph
//! --layout` and every stage after `ingest` run on a layout file (any form: dataset layout, LLM
//! layout, published record), the conversions between the forms, the scene graph of what reads
//! back, and the model-output parser `mesa parse-output` and `mesa tasks` run on replies.
//! Every input must give a value or an error, never a panic or a hang.
#![no_main]

use libfuzzer_sys::fuzz_target;
use mesa_schemas::convert::{dataset_from_llm, llm_from_dataset};
use mesa_schemas::layout_file::{read_layout_text, AnyLayout};
use mesa_schemas::output::parse_model_output;
use mesa_stages::graph::{extract_graph, keyword_containers, GraphConfig, GraphOptions};

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    if let Ok(read) = read_layout_text(text) {
        match &read.layout {
            AnyLayout::Dataset(layout) => {
                let _ = llm_from_dataset(layout);
            }
            AnyLayout::Llm(layout) => {
                let _ = dataset_from_llm(layout);
            }
        }
    }
    if let Ok(loaded) = mesa_stages::graph::read_layout_text(text) {
        let options = GraphOptions::from(&GraphConfig::default());
        let flags = keyword_containers(&loaded.scene, &options);
        if let Ok(graph) = extract_graph(&loaded.scene, &flags, &options) {
            let _ = graph.to_text();
        }
    }
    let _ = parse_model_output(text);
});
