//! One line for an error and its causes, as every program prints it (`error: …` on stderr,
//! the web page, failed-brick messages).
//!
//! Library errors keep their cause as `source()`, and some also name it in their own message
//! (so an HTTP answer, which shows only the message, still says what went wrong). Joining the
//! chain with `": "` would then print that cause twice; [`error_chain`] skips a cause whose text
//! the line already ends with.

use std::error::Error;

/// `error` and its sources, joined by `": "`, each cause left out where the text so far
/// already ends with it.
pub fn error_chain(error: &(dyn Error + 'static)) -> String {
    fn cause<'a>(e: &&'a (dyn Error + 'static)) -> Option<&'a (dyn Error + 'static)> {
        (*e).source()
    }
    join_chain(std::iter::successors(Some(error), cause))
}

/// The messages of `errors` (an error first, then its causes, as `anyhow::Error::chain` gives
/// them) joined by `": "`, each cause left out where the text so far already ends with it.
pub fn join_chain<'a>(errors: impl IntoIterator<Item = &'a (dyn Error + 'static)>) -> String {
    let mut text = String::new();
    for error in errors {
        let message = error.to_string();
        if text.is_empty() {
            text = message;
        } else if !text.ends_with(&message) {
            text.push_str(": ");
            text.push_str(&message);
        }
    }
    text
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, thiserror::Error)]
    enum Outer {
        #[error("a.json: bad multiscales: {source}")]
        Named {
            #[source]
            source: Inner,
        },
        #[error("a.json: not valid JSON")]
        Unnamed {
            #[source]
            source: Inner,
        },
    }

    #[derive(Debug, thiserror::Error)]
    #[error("expected `,` at line 1")]
    struct Inner(#[source] Option<std::io::Error>);

    #[test]
    fn a_cause_already_in_the_message_is_printed_once() {
        let named = Outer::Named {
            source: Inner(None),
        };
        assert_eq!(
            error_chain(&named),
            "a.json: bad multiscales: expected `,` at line 1"
        );
        let unnamed = Outer::Unnamed {
            source: Inner(None),
        };
        assert_eq!(
            error_chain(&unnamed),
            "a.json: not valid JSON: expected `,` at line 1"
        );
        let deep = Outer::Unnamed {
            source: Inner(Some(std::io::Error::other("disk on fire"))),
        };
        assert_eq!(
            error_chain(&deep),
            "a.json: not valid JSON: expected `,` at line 1: disk on fire"
        );
    }
}
