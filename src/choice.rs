//! Named values: one set of names for the command line, JSON files and Python.
//!
//! An option that takes one of a few values (a filter, a mode, a backend) is a Rust
//! enum declared with [`choice_enum!`](crate::choice_enum). The macro gives it
//! - [`Choice`]: every value with its name, its aliases and a one-line help taken from
//!   the variant's doc comment (the command line lists them in `--help`);
//! - `FromStr` and `Display` with those names (errors name the accepted values);
//! - `Serialize`/`Deserialize` as the same strings, so a settings file, a report and
//!   the command line spell a value alike;
//! - an inherent `name()`.
//!
//! ```
//! use voxlab::choice::Choice;
//! use voxlab::settings::Filter;
//!
//! let f: Filter = "catmull-rom".parse()?;
//! assert_eq!(f, Filter::CatmullRom);
//! assert_eq!(f.to_string(), "catmull-rom");
//! assert_eq!("bspline-fast".parse::<Filter>()?, Filter::BsplineFast); // an alias
//! assert!(Filter::CHOICES.iter().any(|c| c.name == "lanczos3"));
//! # Ok::<(), voxlab::Error>(())
//! ```

use crate::error::{Error, Result};

/// One value of a [`Choice`] type.
#[derive(Clone, Copy, Debug)]
pub struct Named<T: 'static> {
    pub value: T,
    /// The name it is written with.
    pub name: &'static str,
    /// Other spellings accepted when reading.
    pub aliases: &'static [&'static str],
    /// The variant's doc comment, lines joined.
    pub doc: &'static str,
}

impl<T> Named<T> {
    /// The doc comment as one line of help: whitespace collapsed, trimmed.
    pub fn help(&self) -> String {
        self.doc.split_whitespace().collect::<Vec<_>>().join(" ")
    }
}

/// A closed set of named values (declared with [`choice_enum!`](crate::choice_enum)).
pub trait Choice: Copy + PartialEq + Sized + 'static {
    /// What a value of this type is, for messages ("filter", "backend").
    const WHAT: &'static str;
    /// Every value, in declaration order.
    const CHOICES: &'static [Named<Self>];

    /// The value's name.
    fn choice_name(self) -> &'static str {
        Self::CHOICES
            .iter()
            .find(|c| c.value == self)
            .map(|c| c.name)
            .expect("choice_enum! names every variant")
    }

    /// The value named `text` (a name or an alias; exact, case-sensitive).
    ///
    /// # Errors
    /// [`Error::Invalid`] naming the accepted values.
    fn parse_choice(text: &str) -> Result<Self> {
        Self::CHOICES
            .iter()
            .find(|c| c.name == text || c.aliases.contains(&text))
            .map(|c| c.value)
            .ok_or_else(|| {
                Error::invalid(
                    Self::WHAT,
                    format!("'{text}' is not {}", or_list(&Self::names())),
                )
            })
    }

    /// The names, in declaration order.
    fn names() -> Vec<&'static str> {
        Self::CHOICES.iter().map(|c| c.name).collect()
    }
}

/// `a`, `a or b`, `a, b or c`.
pub fn or_list(names: &[&str]) -> String {
    match names.split_last() {
        Some((last, rest)) if !rest.is_empty() => format!("{} or {last}", rest.join(", ")),
        Some((last, _)) => last.to_string(),
        None => String::new(),
    }
}

/// Declares an enum whose variants have names (see the [module docs](crate::choice)):
///
/// ```
/// voxlab::choice_enum! {
///     /// How loud.
///     #[derive(Clone, Copy, Debug, PartialEq, Eq)]
///     pub enum Volume: "volume", default Soft {
///         /// Barely.
///         Soft = "soft" | "quiet",
///         /// Very.
///         Loud = "loud",
///     }
/// }
/// assert_eq!("quiet".parse::<Volume>()?, Volume::Soft);
/// assert_eq!(Volume::Loud.name(), "loud");
/// assert_eq!(Volume::default(), Volume::Soft);
/// # Ok::<(), voxlab::Error>(())
/// ```
///
/// The type needs `Copy` and `PartialEq`; only doc comments may stand on a variant.
/// `enum Volume: "volume", default Soft { … }` also implements `Default`.
#[macro_export]
macro_rules! choice_enum {
    (
        $(#[$meta:meta])*
        $vis:vis enum $ty:ident : $what:literal $(, default $default:ident)? {
            $(
                $(#[doc = $doc:literal])*
                $variant:ident = $name:literal $(| $alias:literal)*
            ),+ $(,)?
        }
    ) => {
        $(#[$meta])*
        $vis enum $ty {
            $( $(#[doc = $doc])* $variant, )+
        }

        impl $crate::choice::Choice for $ty {
            const WHAT: &'static str = $what;
            const CHOICES: &'static [$crate::choice::Named<Self>] = &[
                $( $crate::choice::Named {
                    value: $ty::$variant,
                    name: $name,
                    aliases: &[$($alias),*],
                    doc: concat!($($doc, " "),*),
                }, )+
            ];
        }

        $(
            impl ::std::default::Default for $ty {
                fn default() -> Self {
                    $ty::$default
                }
            }
        )?

        impl $ty {
            /// The value's name (on the command line, in JSON and in Python).
            pub fn name(self) -> &'static str {
                match self {
                    $( $ty::$variant => $name, )+
                }
            }
        }

        impl ::std::str::FromStr for $ty {
            type Err = $crate::Error;
            fn from_str(s: &str) -> ::std::result::Result<Self, Self::Err> {
                <$ty as $crate::choice::Choice>::parse_choice(s)
            }
        }

        impl ::std::fmt::Display for $ty {
            fn fmt(&self, f: &mut ::std::fmt::Formatter<'_>) -> ::std::fmt::Result {
                f.write_str(self.name())
            }
        }

        impl ::serde::Serialize for $ty {
            fn serialize<S: ::serde::Serializer>(&self, s: S) -> ::std::result::Result<S::Ok, S::Error> {
                s.serialize_str(self.name())
            }
        }

        impl<'de> ::serde::Deserialize<'de> for $ty {
            fn deserialize<D: ::serde::Deserializer<'de>>(d: D) -> ::std::result::Result<Self, D::Error> {
                let text = <::std::borrow::Cow<'de, str> as ::serde::Deserialize>::deserialize(d)?;
                <$ty as $crate::choice::Choice>::parse_choice(&text).map_err(|_| {
                    ::serde::de::Error::unknown_variant(
                        &text,
                        &[$($name),+],
                    )
                })
            }
        }
    };
}

#[cfg(test)]
mod tests {
    use super::*;

    crate::choice_enum! {
        /// A test type.
        #[derive(Clone, Copy, Debug, PartialEq, Eq)]
        enum Colour: "colour" {
            /// The first
            /// value.
            Red = "red" | "rouge",
            /// The second.
            Green = "green",
        }
    }

    #[test]
    fn names_aliases_and_errors() {
        assert_eq!("rouge".parse::<Colour>().unwrap(), Colour::Red);
        assert_eq!(Colour::Green.to_string(), "green");
        assert_eq!(Colour::CHOICES[0].help(), "The first value.");
        let e = "blue".parse::<Colour>().unwrap_err().to_string();
        assert_eq!(e, "invalid colour: 'blue' is not red or green");
        assert_eq!(serde_json::to_string(&Colour::Red).unwrap(), "\"red\"");
        assert_eq!(
            serde_json::from_str::<Colour>("\"rouge\"").unwrap(),
            Colour::Red
        );
        let e = serde_json::from_str::<Colour>("\"blue\"").unwrap_err();
        assert!(e.to_string().contains("unknown variant `blue`"), "{e}");
        assert_eq!(or_list(&["a", "b", "c"]), "a, b or c");
    }
}
