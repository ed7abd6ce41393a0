//! AWS shared configuration profiles for object stores, which `object_store` does not read: the
//! static keys, session token, region and endpoint of profile `AWS_PROFILE` (default
//! `default`) in `~/.aws/credentials` and `~/.aws/config` (or the files named by
//! `AWS_SHARED_CREDENTIALS_FILE` and `AWS_CONFIG_FILE`). As in the AWS SDKs, variables set in
//! the environment win over the profile, and the credentials file over the config file.
//! Profiles that get credentials from a process, SSO or a role are not followed.

use std::path::{Path, PathBuf};

/// The settings of one profile (each `None` where the profile does not set it).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Profile {
    /// `aws_access_key_id`.
    pub access_key_id: Option<String>,
    /// `aws_secret_access_key`.
    pub secret_access_key: Option<String>,
    /// `aws_session_token`.
    pub session_token: Option<String>,
    /// `region`.
    pub region: Option<String>,
    /// `endpoint_url`.
    pub endpoint_url: Option<String>,
}

/// A profile that cannot be read.
#[derive(Debug, thiserror::Error)]
pub enum ProfileError {
    /// A profile file that exists but cannot be read or parsed.
    #[error("{}: cannot read the AWS profile file: {source}", path.display())]
    Unreadable {
        /// The file.
        path: PathBuf,
        /// Why: the file cannot be read, or is not INI.
        #[source]
        source: ini::Error,
    },
    /// `AWS_PROFILE` names a profile neither file has.
    #[error("AWS profile '{name}' (AWS_PROFILE) is in neither {} nor {}", credentials.display(), config.display())]
    NotFound {
        /// The profile's name.
        name: String,
        /// The credentials file looked in.
        credentials: PathBuf,
        /// The config file looked in.
        config: PathBuf,
    },
}

/// The section of `path` (INI) named `section`; `Ok(None)` when the file or the section is
/// missing.
fn section(
    path: &Path,
    section: &str,
) -> Result<Option<std::collections::HashMap<String, String>>, ProfileError> {
    if !path.exists() {
        return Ok(None);
    }
    let ini = ini::Ini::load_from_file(path).map_err(|source| ProfileError::Unreadable {
        path: path.to_path_buf(),
        source,
    })?;
    Ok(ini.section(Some(section)).map(|props| {
        props
            .iter()
            .map(|(k, v)| (k.trim().to_ascii_lowercase(), v.trim().to_string()))
            .collect()
    }))
}

impl Profile {
    /// Reads profile `name` from the credentials file (section `[name]`) and the config file
    /// (`[profile name]`, or `[default]`). `Ok(None)` when neither has it and it was not asked
    /// for by name (`explicit`).
    ///
    /// # Errors
    /// [`ProfileError::Unreadable`] for a file that cannot be parsed, and
    /// [`ProfileError::NotFound`] for an `explicit` profile that neither file has.
    pub fn read(
        name: &str,
        explicit: bool,
        credentials: &Path,
        config: &Path,
    ) -> Result<Option<Self>, ProfileError> {
        let in_config = if name == "default" {
            "default".to_string()
        } else {
            format!("profile {name}")
        };
        let keys = section(credentials, name)?;
        let settings = section(config, &in_config)?;
        if keys.is_none() && settings.is_none() {
            if explicit {
                return Err(ProfileError::NotFound {
                    name: name.to_string(),
                    credentials: credentials.to_path_buf(),
                    config: config.to_path_buf(),
                });
            }
            return Ok(None);
        }
        let get = |key: &str| {
            keys.as_ref()
                .and_then(|k| k.get(key))
                .or_else(|| settings.as_ref().and_then(|s| s.get(key)))
                .filter(|v| !v.is_empty())
                .cloned()
        };
        Ok(Some(Self {
            access_key_id: get("aws_access_key_id"),
            secret_access_key: get("aws_secret_access_key"),
            session_token: get("aws_session_token"),
            region: get("region"),
            endpoint_url: get("endpoint_url"),
        }))
    }

    /// The profile the environment names (`AWS_PROFILE`, else `default`), from the files it
    /// names (`AWS_SHARED_CREDENTIALS_FILE`, `AWS_CONFIG_FILE`, else under `$HOME/.aws`).
    ///
    /// # Errors
    /// As [`Profile::read`].
    pub fn from_env() -> Result<Option<Self>, ProfileError> {
        let var = |name: &str| std::env::var_os(name).filter(|v| !v.is_empty());
        let home = var("HOME").map(PathBuf::from).unwrap_or_default();
        let file = |variable: &str, default: &str| {
            var(variable).map_or_else(|| home.join(".aws").join(default), PathBuf::from)
        };
        let name = var("AWS_PROFILE").map(|v| v.to_string_lossy().into_owned());
        Self::read(
            name.as_deref().unwrap_or("default"),
            name.is_some(),
            &file("AWS_SHARED_CREDENTIALS_FILE", "credentials"),
            &file("AWS_CONFIG_FILE", "config"),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn credentials_win_over_config_and_missing_profiles_are_named() {
        let dir = tempfile::tempdir().unwrap();
        let credentials = dir.path().join("credentials");
        let config = dir.path().join("config");
        std::fs::write(
            &credentials,
            "[default]\naws_access_key_id = AKDEFAULT\naws_secret_access_key = s0\n\n[lab]\naws_access_key_id=AKLAB\naws_secret_access_key = s1\n",
        )
        .unwrap();
        std::fs::write(
            &config,
            "[default]\nregion = eu-west-1\n\n[profile lab]\nregion = us-east-2\naws_access_key_id = AKIGNORED\nendpoint_url = http://127.0.0.1:9000\n\n[profile only-config]\naws_access_key_id = AKCONF\n",
        )
        .unwrap();
        let lab = Profile::read("lab", true, &credentials, &config).unwrap();
        assert_eq!(
            lab,
            Some(Profile {
                access_key_id: Some("AKLAB".into()),
                secret_access_key: Some("s1".into()),
                session_token: None,
                region: Some("us-east-2".into()),
                endpoint_url: Some("http://127.0.0.1:9000".into()),
            })
        );
        let default = Profile::read("default", false, &credentials, &config).unwrap();
        assert_eq!(
            default.map(|p| (p.access_key_id, p.region)),
            Some((Some("AKDEFAULT".into()), Some("eu-west-1".into())))
        );
        let conf = Profile::read("only-config", true, &credentials, &config).unwrap();
        assert_eq!(conf.unwrap().access_key_id.as_deref(), Some("AKCONF"));
        let missing = dir.path().join("nothing");
        assert_eq!(
            Profile::read("default", false, &missing, &missing).unwrap(),
            None
        );
        assert_eq!(
            Profile::read("nope", true, &credentials, &config)
                .unwrap_err()
                .to_string(),
            format!(
                "AWS profile 'nope' (AWS_PROFILE) is in neither {} nor {}",
                credentials.display(),
                config.display()
            )
        );
    }
}
