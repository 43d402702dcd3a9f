"""Log-in from an LMS course (Canvas, Moodle, ...): LTI 1.3 with jupyterhub-ltiauthenticator.

Read by jupyterhub_config.py when SNAKEKIT_AUTH=lti. Register the hub in the LMS as an LTI 1.3
tool ("developer key" in Canvas, "External tool" in Moodle) with its endpoints
(<hub>/hub/lti13/oauth_login, <hub>/hub/lti13/oauth_callback, <hub>/hub/lti13/jwks; the JSON
configuration at <hub>/hub/lti13/config), then set here what the LMS shows:

  SNAKEKIT_LTI_ISSUER         the platform's issuer   (Canvas: https://canvas.instructure.com)
  SNAKEKIT_LTI_CLIENT_IDS     the tool's client id(s), comma-separated
  SNAKEKIT_LTI_AUTHORIZE_URL  the platform's OIDC auth endpoint
                              (Canvas: https://<canvas host>/api/lti/authorize_redirect)
  SNAKEKIT_LTI_JWKS_URL       the platform's key set (Canvas: https://<canvas host>/api/lti/security/jwks)
  SNAKEKIT_LTI_USERNAME_KEY   the claim that becomes the hub user name (default: the LMS's
                              stable id "sub"; "email" or "custom_<name>" also work)

The user names are what nbgrader knows the students as (course/roster.csv's `student`).
Instructors and TAs are then added to the hub group `instructors` (docker/hub/README.md).
`docker/hub/check-config` loads this file and checks every setting against the
authenticator's own configuration classes.
"""
import os

c = get_config()  # noqa: F821 (JupyterHub provides it)
c.JupyterHub.authenticator_class = "ltiauthenticator.lti13.auth.LTI13Authenticator"
c.LTI13Authenticator.issuer = os.environ.get("SNAKEKIT_LTI_ISSUER", "https://canvas.instructure.com")
c.LTI13Authenticator.client_id = [i for i in os.environ.get("SNAKEKIT_LTI_CLIENT_IDS", "").split(",") if i]
c.LTI13Authenticator.authorize_url = os.environ.get("SNAKEKIT_LTI_AUTHORIZE_URL",
                                                    "https://canvas.example.edu/api/lti/authorize_redirect")
c.LTI13Authenticator.jwks_endpoint = os.environ.get("SNAKEKIT_LTI_JWKS_URL",
                                                    "https://canvas.example.edu/api/lti/security/jwks")
c.LTI13Authenticator.username_key = os.environ.get("SNAKEKIT_LTI_USERNAME_KEY", "sub")
c.LTI13Authenticator.uri_scheme = "https"  # behind the university's TLS front end
c.LTI13Authenticator.tool_name = "snakekit"
c.LTI13Authenticator.tool_description = "Robot control on a 5-joint arm: lessons and graded exercises"
c.Authenticator.allow_all = True  # whoever the LMS sends from the course
