//! The command line as packaged: shell completions and the man page come from the same
//! definition as the parser, so they name every subcommand and option.

use std::process::Command;

fn stdout(args: &[&str]) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_crease")).args(args).output().unwrap();
    assert!(out.status.success(), "{args:?}: {}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8(out.stdout).unwrap()
}

#[test]
fn completions_and_man_page_cover_the_commands() {
    for shell in ["bash", "zsh", "fish"] {
        let script = stdout(&["completions", shell]);
        // (fish names long options without their dashes.)
        for word in ["extract", "min-confidence", "a-srs", "recursive"] {
            assert!(script.contains(word), "{shell} completions lack {word}");
        }
    }
    let man = stdout(&["man"]);
    assert!(man.starts_with(".ie") && man.contains(".TH crease 1"), "{}", &man[..200.min(man.len())]);
    for word in ["extract", "status", "eval", "synth"] {
        assert!(man.contains(word), "man page lacks {word}");
    }
}
