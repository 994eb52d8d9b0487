//! What a caught panic said.

use std::any::Any;

/// The message of a panic's payload (`panic!("…")` gives a `&str` or a `String`);
/// `None` for a payload of another type.
pub fn panic_text(payload: &(dyn Any + Send)) -> Option<&str> {
    payload.downcast_ref::<&str>().copied().or_else(|| payload.downcast_ref::<String>().map(String::as_str))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_text_of_a_literal_a_formatted_and_an_odd_payload() {
        let literal = std::panic::catch_unwind(|| panic!("plain")).unwrap_err();
        let formatted = std::panic::catch_unwind(|| panic!("{} words", 2)).unwrap_err();
        let odd = std::panic::catch_unwind(|| std::panic::panic_any(7u8)).unwrap_err();
        assert_eq!(panic_text(literal.as_ref()), Some("plain"));
        assert_eq!(panic_text(formatted.as_ref()), Some("2 words"));
        assert_eq!(panic_text(odd.as_ref()), None);
    }
}
